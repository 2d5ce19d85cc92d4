/*
 * A C host that plays the scanner for capsule-mpc's C ABI.
 *
 * Plant: two capsules on one gradient u (T/m):
 *   x' = v,  v' = -b v|v| + g u,  g = 173.25, b = 134.7 and 16.84 1/m,
 * integrated with RK4 at 1 ms. Timeline per cycle: tracking 20 ms (u = 0,
 * positions measured at its start), then the actuation samples the
 * controller returns (20 ms each). Scenario C: target (0.02, 0, -0.01, 0) m
 * from rest at the origin, 3 s of simulated time.
 *
 * Usage: c_host [mode] [noise_m]   mode 0 ideal, 1 constant (default),
 *        2 variable; noise_m: amplitude of deterministic measurement noise
 *        (default 5e-5 m).
 * Exit status 0 only when both positions end within 1 mm of the target.
 */
#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>

#include "capsule_mpc.h"

#define NCAP 2
#define STEP_S 0.001
#define TRACKING_S 0.020
#define SIM_END_S 3.0
#define TOL_M 0.001
#define MAX_PLAN 256

static const double G[NCAP] = {173.25, 173.25};
static const double B[NCAP] = {134.7, 16.84};

/* Workspace: static, generously sized and aligned; checked at run time. */
static _Alignas(64) unsigned char workspace[1 << 16];

static void deriv(const double s[2 * NCAP], double u, double d[2 * NCAP]) {
    for (int i = 0; i < NCAP; i++) {
        double v = s[2 * i + 1];
        d[2 * i] = v;
        d[2 * i + 1] = -B[i] * v * fabs(v) + G[i] * u;
    }
}

static void rk4_step(double s[2 * NCAP], double u, double h) {
    double k1[2 * NCAP], k2[2 * NCAP], k3[2 * NCAP], k4[2 * NCAP], t[2 * NCAP];
    deriv(s, u, k1);
    for (int j = 0; j < 2 * NCAP; j++) t[j] = s[j] + 0.5 * h * k1[j];
    deriv(t, u, k2);
    for (int j = 0; j < 2 * NCAP; j++) t[j] = s[j] + 0.5 * h * k2[j];
    deriv(t, u, k3);
    for (int j = 0; j < 2 * NCAP; j++) t[j] = s[j] + h * k3[j];
    deriv(t, u, k4);
    for (int j = 0; j < 2 * NCAP; j++) s[j] += h / 6.0 * (k1[j] + 2.0 * k2[j] + 2.0 * k3[j] + k4[j]);
}

/* Holds u for duration_s (a whole number of 1 ms steps). */
static void hold(double s[2 * NCAP], double u, double duration_s, double *t) {
    long steps = lround(duration_s / STEP_S);
    for (long k = 0; k < steps; k++) rk4_step(s, u, STEP_S);
    *t += steps * STEP_S;
}

/* Deterministic noise in [-1, 1] (LCG). */
static double noise(uint32_t *seed) {
    *seed = *seed * 1664525u + 1013904223u;
    return ((double)(*seed >> 8) / (double)(1u << 24)) * 2.0 - 1.0;
}

#define CHECK(call)                                                         \
    do {                                                                    \
        int32_t rc_ = (call);                                               \
        if (rc_ != CAPSULE_MPC_OK) {                                        \
            fprintf(stderr, "%s failed: error %d\n", #call, (int)rc_);      \
            return 2;                                                       \
        }                                                                   \
    } while (0)

int main(int argc, char **argv) {
    int mode = argc > 1 ? atoi(argv[1]) : CAPSULE_MPC_SAMPLING_CONSTANT;
    double noise_m = argc > 2 ? atof(argv[2]) : 5e-5;

    uint32_t capsules = 0, horizon = 0, plan_len = 0;
    double dt_s = 0.0, u_max = 0.0;
    CHECK(capsule_mpc_dimensions(&capsules, &horizon, &plan_len, &dt_s, &u_max));
    size_t ws_size = capsule_mpc_workspace_size();
    size_t ws_align = capsule_mpc_workspace_align();
    printf("# capsule_mpc abi %u: capsules %u, horizon %u, plan %u, dt %.3f s, u_max %.3f T/m\n",
           capsule_mpc_abi_version(), capsules, horizon, plan_len, dt_s, u_max);
    printf("# workspace_size %zu bytes, align %zu\n", ws_size, ws_align);
    if (capsule_mpc_abi_version() != CAPSULE_MPC_ABI_VERSION || capsules != NCAP || plan_len > MAX_PLAN ||
        ws_size > sizeof workspace || ws_align > 64) {
        fprintf(stderr, "library build does not match this host\n");
        return 2;
    }

    const double start[NCAP] = {0.0, 0.0};
    const double target[2 * NCAP] = {0.02, 0.0, -0.01, 0.0};
    CHECK(capsule_mpc_init(workspace, sizeof workspace, start, NCAP));
    capsule_mpc_t *h = (capsule_mpc_t *)workspace;
    CHECK(capsule_mpc_set_sampling(h, mode));
    CHECK(capsule_mpc_set_target(h, target, 2 * NCAP));

    double s[2 * NCAP] = {start[0], 0.0, start[1], 0.0};
    double t = 0.0;
    double grads[MAX_PLAN];
    uint32_t seed = 12345u;
    int cycles = 0, non_ok = 0;
    printf("# t_s x1_m x2_m u_T_per_m samples status\n");
    while (t < SIM_END_S - 1e-9) {
        if (mode == CAPSULE_MPC_SAMPLING_IDEAL) {
            /* Ideal: no tracking phase, the full state is known. */
            CHECK(capsule_mpc_feed_state(h, s, 2 * NCAP));
        } else {
            double z[NCAP];
            for (int i = 0; i < NCAP; i++) z[i] = s[2 * i] + noise_m * noise(&seed);
            double t_meas = t;
            hold(s, 0.0, TRACKING_S, &t); /* tracking phase, gradients off */
            CHECK(capsule_mpc_feed_tracking(h, z, NCAP, t_meas, 0));
        }
        uint32_t samples = 0;
        int32_t status = 0;
        CHECK(capsule_mpc_next_actuation(h, grads, plan_len, &samples, &status));
        if (status != CAPSULE_MPC_STATUS_OK) non_ok++;
        for (uint32_t k = 0; k < samples; k++) {
            double u = grads[k];
            if (!(fabs(u) <= u_max)) {
                fprintf(stderr, "gradient out of bounds: %g\n", u);
                return 2;
            }
            printf("%.3f %.6f %.6f %+.5f %u %d\n", t, s[0], s[2], u, samples, (int)status);
            hold(s, u, dt_s, &t);
        }
        cycles++;
    }
    double e1 = s[0] - target[0], e2 = s[2] - target[2];
    printf("# end t %.3f s after %d cycles (%d not OK): x1 %.6f m, x2 %.6f m, v1 %.2e, v2 %.2e\n", t, cycles,
           non_ok, s[0], s[2], s[1], s[3]);
    printf("# final error: |x1 - x1*| = %.3f mm, |x2 - x2*| = %.3f mm (tolerance %.1f mm)\n", fabs(e1) * 1e3,
           fabs(e2) * 1e3, TOL_M * 1e3);
    if (fabs(e1) <= TOL_M && fabs(e2) <= TOL_M) {
        printf("# PASS\n");
        return 0;
    }
    printf("# FAIL\n");
    return 1;
}
