# The capsule-mpc binary in a small image, for sharded table generation on
# Kubernetes (deploy/k8s/) or any container runtime:
#
#   docker build -t capsule-mpc:latest .
#   docker run --rm -v "$PWD/out:/work" capsule-mpc:latest generate --rounds
#
# The build stage compiles the workspace as CI does (the generated crate is
# compiled in, so `generate --merge` can measure the QP iteration map when
# the config is the shipped one).
FROM rust:1-bookworm AS build
WORKDIR /src
COPY . .
RUN cargo build --release --locked --bin capsule-mpc

FROM debian:bookworm-slim
COPY --from=build /src/target/release/capsule-mpc /usr/local/bin/capsule-mpc
COPY configs /opt/capsule-mpc/configs
COPY deploy/k8s/shard.sh /usr/local/bin/capsule-shard
WORKDIR /work
ENTRYPOINT ["capsule-mpc"]
