#!/bin/sh
# Builds the capsule-mpc C library, this C host and the mismatch grid
# (plant_grid.c), then runs the host.
# Usage: ./build.sh [mode] [noise_m] [tracking_s] [glitch_frames] [glitch_m]
# (mode 0 ideal, 1 constant, 2 variable; see main.c)
set -eu
cd "$(dirname "$0")"
cargo build --release -p capsule-mpc-capi
gcc -Wall -Wextra -Werror -std=c11 -O2 main.c -I ../../capi/include \
    ../../target/release/libcapsule_mpc_capi.a -lm -lpthread -ldl -o c_host
gcc -Wall -Wextra -Werror -std=c11 -O2 plant_grid.c -I ../../capi/include \
    ../../target/release/libcapsule_mpc_capi.a -lm -lpthread -ldl -o plant_grid
./c_host "$@"
