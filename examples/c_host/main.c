/*
 * A C host that plays the scanner for capsule-mpc's C ABI.
 *
 * Plant: two capsules on one gradient u (T/m):
 *   x' = v,  v' = -b v|v| + g u,  g = 173.25, b = 134.7 and 16.84 1/m,
 * integrated with RK4 at 1 ms. Timeline per cycle: a tracking phase (u = 0,
 * positions measured at its start, 20 ms by default, or a length drawn
 * between 10 and 30 ms every cycle), then the actuation samples the
 * controller returns (20 ms each), time-stamped on the host's clock.
 * Scenario C: target (0.02, 0, -0.01, 0) m from rest at the origin.
 *
 * Usage: c_host [mode] [noise_m] [tracking_s] [glitch_frames] [glitch_m] [refine]
 *        mode 0 ideal, 1 constant (default), 2 variable; noise_m: amplitude
 *        of deterministic measurement noise (default 5e-5 m); tracking_s:
 *        tracking phase length (default 0.02; 0 = jitter 10-30 ms; beyond
 *        capsule_mpc_max_gap_s(), 30 ms, refused at set-up);
 *        glitch_frames / glitch_m: that many frames from 2 s on report both
 *        positions glitch_m off (default 0 / 0.05).
 * Exit status 0 only when the capsules settle (both positions within 1 mm
 * of the target, both speeds below 5 mm/s, held for 1 s) no later than 3 s
 * (default tracking; 6 s with other tracking lengths, whose duty is lower)
 * or, with a glitch, 3 s after its last frame.
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
#define GLITCH_START_S 2.0
#define TOL_M 0.001
#define SPEED_TOL 0.005
#define HELD_S 1.0
#define RECOVERY_S 3.0
#define LONG_TRACKING_DEADLINE_S 6.0
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
    double tracking_s = argc > 3 ? atof(argv[3]) : TRACKING_S;
    int glitch_frames = argc > 4 ? atoi(argv[4]) : 0;
    double glitch_m = argc > 5 ? atof(argv[5]) : 0.05;
    /* CAPSULE_MPC_REFINE_*: when the SQP refinement runs after the explicit tier. */
    int refine = argc > 6 ? atoi(argv[6]) : CAPSULE_MPC_REFINE_PER_SAMPLE;

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
    CHECK(capsule_mpc_set_refine(h, refine));
    /* The tracking phase the plans model until the first gaps are measured
     * (the jitter's longest); refused beyond the proven range. */
    CHECK(capsule_mpc_set_timing(h, tracking_s > 0.0 ? tracking_s : 0.030, 0.0));
    CHECK(capsule_mpc_set_target(h, target, 2 * NCAP));

    double s[2 * NCAP] = {start[0], 0.0, start[1], 0.0};
    double t = 0.0;
    double grads[MAX_PLAN];
    uint32_t seed = 12345u, jitter_seed = 777u;
    int cycles = 0, non_ok = 0, glitched = 0;
    int counts[16] = {0};
    int tier_explicit = 0, tier_refined = 0;
    /* Settled = both positions within TOL_M of the target and both speeds
     * below SPEED_TOL for HELD_S in a row; it must start by the deadline. */
    double deadline_s = tracking_s == TRACKING_S ? SIM_END_S : LONG_TRACKING_DEADLINE_S;
    double last_bad_s = 0.0, band_since = -1.0, settled_s = -1.0;
    printf("# t_s x1_m x2_m u_T_per_m samples status\n");
    while (t < deadline_s + HELD_S - 1e-9 && settled_s < 0.0) {
        if (mode == CAPSULE_MPC_SAMPLING_IDEAL) {
            /* Ideal: no tracking phase, the full state is known. */
            CHECK(capsule_mpc_feed_state(h, s, 2 * NCAP));
        } else {
            double z[NCAP];
            for (int i = 0; i < NCAP; i++) z[i] = s[2 * i] + noise_m * noise(&seed);
            if (glitched < glitch_frames && t >= GLITCH_START_S - 1e-9) {
                for (int i = 0; i < NCAP; i++) z[i] += glitch_m;
                glitched++;
                last_bad_s = t;
                deadline_s = t + RECOVERY_S;
                band_since = -1.0;
            }
            double t_meas = t;
            /* Tracking phase, gradients off: fixed, or 10-30 ms in whole ms. */
            double track = tracking_s > 0.0 ? tracking_s : 0.001 * (10 + (int)((noise(&jitter_seed) + 1.0) * 10.49));
            hold(s, 0.0, track, &t);
            CHECK(capsule_mpc_feed_tracking(h, z, NCAP, t_meas, 0));
        }
        uint32_t samples = 0;
        int32_t status = 0;
        /* The actuation starts now, at the end of tracking. */
        CHECK(capsule_mpc_next_actuation(h, t, grads, plan_len, &samples, &status));
        if (status != CAPSULE_MPC_STATUS_OK) non_ok++;
        if (status >= 0 && status < 16) counts[status]++;
        int32_t tier = CAPSULE_MPC_TIER_NONE;
        CHECK(capsule_mpc_last_tier(h, &tier));
        if (tier == CAPSULE_MPC_TIER_EXPLICIT) tier_explicit++;
        if (tier == CAPSULE_MPC_TIER_REFINED) tier_refined++;
        for (uint32_t k = 0; k < samples; k++) {
            double u = grads[k];
            if (!(fabs(u) <= u_max)) {
                fprintf(stderr, "gradient out of bounds: %g\n", u);
                return 2;
            }
            printf("%.3f %.6f %.6f %+.5f %u %d\n", t, s[0], s[2], u, samples, (int)status);
            hold(s, u, dt_s, &t);
            int inside = fabs(s[0] - target[0]) <= TOL_M && fabs(s[2] - target[2]) <= TOL_M &&
                         fabs(s[1]) < SPEED_TOL && fabs(s[3]) < SPEED_TOL;
            if (!inside) {
                band_since = -1.0;
            } else if (band_since < 0.0) {
                band_since = t;
            } else if (t - band_since >= HELD_S - 1e-9 && glitched >= glitch_frames) {
                settled_s = band_since > last_bad_s ? band_since : last_bad_s;
                break;
            }
        }
        cycles++;
    }
    printf("# statuses: ok %d, fallback %d, rejected %d, lost %d, reacquired %d, recovering %d\n",
           counts[CAPSULE_MPC_STATUS_OK], counts[CAPSULE_MPC_STATUS_FALLBACK],
           counts[CAPSULE_MPC_STATUS_MEASUREMENT_REJECTED], counts[CAPSULE_MPC_STATUS_MEASUREMENT_LOST],
           counts[CAPSULE_MPC_STATUS_REACQUIRED], counts[CAPSULE_MPC_STATUS_RECOVERING]);
    printf("# plans from the explicit tier %d, from the refinement %d (refine mode %d)\n", tier_explicit,
           tier_refined, refine);
    printf("# end t %.3f s after %d cycles (%d not OK): x1 %.6f m, x2 %.6f m, v1 %.2e, v2 %.2e\n", t, cycles,
           non_ok, s[0], s[2], s[1], s[3]);
    if (glitch_frames > 0) printf("# last glitch frame at %.3f s\n", last_bad_s);
    if (settled_s >= 0.0 && settled_s <= deadline_s + 1e-9) {
        printf("# settled (within %.1f mm, below %.0f mm/s, held %.1f s) from %.3f s, deadline %.3f s\n# PASS\n",
               TOL_M * 1e3, SPEED_TOL * 1e3, HELD_S, settled_s, deadline_s);
        return 0;
    }
    printf("# not settled by the deadline %.3f s\n# FAIL\n", deadline_s);
    return 1;
}
