/*
 * capsule_mpc.h - C ABI of the capsule-mpc runtime (crate capsule-mpc-capi).
 *
 * Hand-written; capi/tests/header.rs checks it against capi/src/lib.rs
 * (every function, its parameter count, every constant value).
 *
 * Memory: the caller owns everything. Ask capsule_mpc_workspace_size() and
 * capsule_mpc_workspace_align(), provide a buffer, capsule_mpc_init() builds
 * the controller in it; the handle is that buffer. No call allocates.
 * Not thread-safe per handle; separate handles are independent.
 *
 * Every function returns CAPSULE_MPC_OK (0) or a negative error code, except
 * the four constant queries. On error nothing changes and no output is
 * written. Units: SI (m, m/s, s, T/m). Times are the host's scanner clock in
 * seconds (any origin; it restarts at init and reset).
 *
 * Call order:
 *   capsule_mpc_dimensions / capsule_mpc_abi_version   (check the build)
 *   capsule_mpc_init(buf, size, positions, M)
 *   capsule_mpc_set_sampling(h, mode)                  (optional, before the loop)
 *   capsule_mpc_set_timing(h, tracking_s, delay_s)     (optional, before the loop)
 *   capsule_mpc_set_target(h, target, 2M)
 *   loop: tracking phase (u = 0), then
 *         capsule_mpc_feed_tracking(h, positions, M, t_measured, lost)
 *           (ideal sampling: capsule_mpc_feed_state instead)
 *         capsule_mpc_next_actuation(h, t_actuation_start, grads, cap, &samples, &status)
 *         play grads[0..samples), one per sample time, from t_actuation_start
 *
 * Timing: the controller predicts its estimate from the end of the last
 * actuation phase (its start + samples x sample time) through the
 * measurement to the actuation start you give, and plans for the gaps these
 * times show. Tracking phases may vary from cycle to cycle; report the
 * true times. Proven range, enforced: tracking + delay per cycle (end of
 * one actuation phase to the start of the next) of at most
 * capsule_mpc_max_gap_s(), the generated config's tracking time + delay +
 * 10 ms (30 ms for the default config). Over a 1 cm grid of targets in
 * +-4 cm (0.2 mm noise, the paper's disturbance, seeds 1-8, 640 runs per
 * sampling) every run settles with 30 ms gaps, the worst at 6.2 s
 * constant / 3.8 s variable against 2.6 / 5.2 s with 20 ms (within 3x);
 * with 40 ms the constant worst is 2.9x, with 50 ms some runs do not
 * settle in 10 s, with 80 ms half of them (docs/known-limits.md). So the
 * loop refuses, with
 * CAPSULE_MPC_ERR_GAP_BEYOND_PROVEN: capsule_mpc_set_timing beyond it (at
 * set-up), and any cycle whose measurement or actuation start lies more
 * than capsule_mpc_max_gap_s() (+ 1 ms) after the end of the last
 * actuation phase; after such a pause, call capsule_mpc_reset. For a
 * longer tracking phase, regenerate the controller with it
 * (scanner.tracking_time_s). A measurement more than 1 ms before the end
 * of the last actuation phase (time going backwards), or an actuation
 * start before its measurement, is refused with CAPSULE_MPC_ERR_BAD_TIME.
 */
#ifndef CAPSULE_MPC_H
#define CAPSULE_MPC_H

#include <stddef.h>
#include <stdint.h>

#ifdef __cplusplus
extern "C" {
#endif

#define CAPSULE_MPC_ABI_VERSION 6u

/* Error codes. */
#define CAPSULE_MPC_OK 0
#define CAPSULE_MPC_ERR_NULL_POINTER (-1)
#define CAPSULE_MPC_ERR_BAD_SIZE (-2)
#define CAPSULE_MPC_ERR_BAD_ALIGN (-3)
#define CAPSULE_MPC_ERR_WRONG_LENGTH (-4)
#define CAPSULE_MPC_ERR_NON_FINITE (-5)
#define CAPSULE_MPC_ERR_TARGET_OUT_OF_RANGE (-6)
#define CAPSULE_MPC_ERR_BAD_MODE (-7)        /* not a CAPSULE_MPC_SAMPLING_* value */
#define CAPSULE_MPC_ERR_NOT_INITIALIZED (-8)
#define CAPSULE_MPC_ERR_BAD_SETTING (-9)
#define CAPSULE_MPC_ERR_BAD_TIME (-10)       /* time going backwards (see Timing) */
#define CAPSULE_MPC_ERR_WRONG_FEED (-11)     /* feed_state outside ideal sampling, feed_tracking in it */
#define CAPSULE_MPC_ERR_LOOP_RUNNING (-12)   /* set_sampling/set_timing after the loop started: reset first */
#define CAPSULE_MPC_ERR_TARGET_NOT_AT_REST (-13) /* a target speed is not 0 */
#define CAPSULE_MPC_ERR_CORRUPT_TABLES (-14) /* the compiled-in table file failed its SHA-256 check */
#define CAPSULE_MPC_ERR_GAP_BEYOND_PROVEN (-15) /* tracking + delay > capsule_mpc_max_gap_s() (see Timing) */

/* Sampling modes (capsule_mpc_set_sampling). */
#define CAPSULE_MPC_SAMPLING_IDEAL 0
#define CAPSULE_MPC_SAMPLING_CONSTANT 1
#define CAPSULE_MPC_SAMPLING_VARIABLE 2

/* Refinement modes (capsule_mpc_set_refine). */
#define CAPSULE_MPC_REFINE_NONE 0
#define CAPSULE_MPC_REFINE_ONCE 1
#define CAPSULE_MPC_REFINE_PER_SAMPLE 2

/* Solver tiers (capsule_mpc_last_tier). */
#define CAPSULE_MPC_TIER_NONE (-1)
#define CAPSULE_MPC_TIER_EXPLICIT 0
#define CAPSULE_MPC_TIER_REFINED 1

/* Cycle status (capsule_mpc_next_actuation, capsule_mpc_last_status).
 * Whatever the status, the plan is finite and within |u| <= u_max: play it.
 * What each means for the host:
 *   OK                  nominal.
 *   FALLBACK            the state is outside the tables: one braking sample
 *                       that leaves the capsules the least distance to coast.
 *                       Keep the loop running: the controller plans again as
 *                       soon as the state is back in range, or, at rest,
 *                       starts RECOVERING. Persistent FALLBACK at rest means
 *                       the estimate disagrees with the frames (the legs are
 *                       not re-planned then): check tracking.
 *   ITERATION_LIMIT     a QP hit its bound; the best feasible plan. Log it.
 *   MEASUREMENT_REJECTED the frame was implausible (non-finite, |x| > 1 m,
 *                       beyond the 5-sigma gate, or part of a glitch: up to
 *                       20 frames that contradict an established estimate);
 *                       the estimate was predicted only. Check tracking if
 *                       it persists.
 *   MEASUREMENT_LOST    no frame (lost or none fed): predicted only.
 *   NO_TARGET           zero gradient: set a target.
 *   REACQUIRED          the estimate jumped to the frames (after a wrong reset,
 *                       5 agreeing frames; against an established estimate,
 *                       21) with the positions and speeds they show, or back
 *                       to the estimate they had replaced when frames return
 *                       to it (a glitch ended). The plan restarted. Log it.
 *   ABOVE_ITERATION_MAP a QP took more iterations than measured offline for
 *                       this state; the plan is converged. Log it.
 *   RECOVERING          after a FALLBACK outside the tables with every speed
 *                       below 20 mm/s, the controller re-planned its chained
 *                       legs from where the capsules are: stored plans
 *                       through waypoints toward the target, reported until
 *                       the last leg. Keep the loop running. */
#define CAPSULE_MPC_STATUS_OK 0
#define CAPSULE_MPC_STATUS_FALLBACK 1
#define CAPSULE_MPC_STATUS_ITERATION_LIMIT 2
#define CAPSULE_MPC_STATUS_MEASUREMENT_REJECTED 3
#define CAPSULE_MPC_STATUS_MEASUREMENT_LOST 4
#define CAPSULE_MPC_STATUS_NO_TARGET 5
#define CAPSULE_MPC_STATUS_REACQUIRED 6
#define CAPSULE_MPC_STATUS_ABOVE_ITERATION_MAP 7
#define CAPSULE_MPC_STATUS_RECOVERING 8

/* Opaque controller; a handle is the buffer given to capsule_mpc_init. */
typedef struct capsule_mpc capsule_mpc_t;

uint32_t capsule_mpc_abi_version(void);

/* Bytes and alignment of the buffer capsule_mpc_init needs (they depend on
 * the generated config: always ask). */
size_t capsule_mpc_workspace_size(void);
size_t capsule_mpc_workspace_align(void);

/* The longest tracking + delay per cycle the loop accepts, s (the proven
 * range, see Timing). */
double capsule_mpc_max_gap_s(void);

/* Build dimensions: capsule count M, online horizon N (the largest number of
 * samples one cycle returns), plan length, sample time and gradient bound. */
int32_t capsule_mpc_dimensions(uint32_t *capsules, uint32_t *horizon, uint32_t *plan_len,
                               double *sample_time_s, double *u_max_t_per_m);

/* Builds a controller in buffer (size bytes, aligned): capsules at rest at
 * positions_m[0..n_positions), n_positions = M; constant sampling; no target.
 * Every position must lie in the workspace (as a target's), else
 * TARGET_OUT_OF_RANGE. */
int32_t capsule_mpc_init(void *buffer, size_t size, const double *positions_m, size_t n_positions);

/* Restarts the estimate at rest at positions_m (n = M, inside the workspace,
 * else TARGET_OUT_OF_RANGE); keeps the target and the mode; drops a fed
 * frame; restarts the clock; allows set_sampling. */
int32_t capsule_mpc_reset(capsule_mpc_t *handle, const double *positions_m, size_t n);

/* Target [x1, v1, x2, v2, ...] (n = 2M). Speeds must be 0
 * (CAPSULE_MPC_ERR_TARGET_NOT_AT_REST); every position must lie in the
 * workspace the solver was generated for (default [-0.06, 0.06] m), else
 * TARGET_OUT_OF_RANGE. Reached from wherever the capsules are, moving or
 * not, through waypoints (chained stored plans) when one plan is not
 * enough. The way there is not bounded by the workspace: a minimum-time
 * move swings the low-drag capsule past its target, for the default config
 * up to about 4-6 cm outside (docs/known-limits.md). */
int32_t capsule_mpc_set_target(capsule_mpc_t *handle, const double *target, size_t n);

/* CAPSULE_MPC_SAMPLING_*; restarts the estimate at rest at the current
 * estimated positions (keeps the target). Only before the loop: after init
 * or reset and before the next capsule_mpc_next_actuation, otherwise
 * CAPSULE_MPC_ERR_LOOP_RUNNING (setting the current mode is always OK). */
int32_t capsule_mpc_set_sampling(capsule_mpc_t *handle, int32_t mode);

/* The tracking phase and the extra delay after it, s, that the plans model
 * until time-stamped cycles have measured the gaps (default: the generated
 * config's). Only before the loop, as set_sampling (LOOP_RUNNING after).
 * GAP_BEYOND_PROVEN when their sum exceeds capsule_mpc_max_gap_s(),
 * BAD_SETTING when one is negative, NON_FINITE when one is not finite. */
int32_t capsule_mpc_set_timing(capsule_mpc_t *handle, double tracking_time_s, double extra_delay_s);

/* The disturbance the estimator assumes: a bound on the norm of the additive
 * disturbance of the state derivative, SI (m/s on the position rates, m/s^2
 * on the accelerations; the paper's 0.05 in cm units is 5e-4). Default: the
 * generated config's [disturbance] bound (5e-4 for the default config), with
 * which the docs' figures were measured; 0 tells the estimator the capsules
 * move exactly as modelled. Only before the loop, as set_timing
 * (LOOP_RUNNING after). BAD_SETTING when negative or above 1e3, NON_FINITE
 * when not finite. */
int32_t capsule_mpc_set_disturbance_bound(capsule_mpc_t *handle, double bound_si);

/* One tracking frame (constant or variable sampling; WRONG_FEED under ideal):
 * positions (n = M) measured at the start of the tracking phase that just
 * ended, at time t_measured_s (finite; BAD_TIME / GAP_BEYOND_PROVEN, see Timing). lost != 0: no
 * frame (positions_m may be NULL). A later feed replaces an earlier one. */
int32_t capsule_mpc_feed_tracking(capsule_mpc_t *handle, const double *positions_m, size_t n,
                                  double t_measured_s, int32_t lost);

/* Full state [x1, v1, x2, v2, ...] (n = 2M), ideal sampling only (WRONG_FEED
 * otherwise). */
int32_t capsule_mpc_feed_state(capsule_mpc_t *handle, const double *state, size_t n);

/* Runs one cycle on the fed frame (none fed = lost) for an actuation that
 * starts at t_actuation_start_s (finite; BAD_TIME / GAP_BEYOND_PROVEN, see
 * Timing; unused under
 * ideal sampling) and writes gradients_t_per_m[0..min(capacity, plan_len));
 * play the first *samples, one per sample time, from the actuation start.
 * capacity >= horizon. */
int32_t capsule_mpc_next_actuation(capsule_mpc_t *handle, double t_actuation_start_s,
                                   double *gradients_t_per_m, size_t capacity, uint32_t *samples,
                                   int32_t *status);

/* When the SQP refinement runs after the explicit tier (which always runs
 * first; a refined plan replaces its plan only when its true cost is
 * lower): CAPSULE_MPC_REFINE_NONE (the explicit tier alone: bounded time,
 * no model rollout), _ONCE (one refinement per cycle), _PER_SAMPLE (one
 * per sample the coming phase plays; the default). Any time; BAD_MODE for
 * another value. */
int32_t capsule_mpc_set_refine(capsule_mpc_t *handle, int32_t mode);

/* Minimum-time shots (on != 0): the plan is the shortest one that ends at the
 * target at rest, re-solved every cycle, wherever one converges; on == 0:
 * the refinement of the stored plans alone. Default without a call: on,
 * under every sampling mode (docs/decisions.md). Any time. */
int32_t capsule_mpc_set_shooting(capsule_mpc_t *handle, int32_t on);

/* What is known of capsule `capsule`'s (0-based) gain and drag against the
 * model, e.g. from `capsule-mpc calibrate`: factors (1 = the model) and
 * their standard deviations. They replace the estimate; the plans use them
 * at once where they differ from the model significantly, and the frames
 * keep refining them; kept across capsule_mpc_reset. Called before the
 * first cycle (after create or reset), the gain's deviation also sets how
 * sure the estimator is of the capsules' starting speeds: 1 % makes the
 * short moves' first arrivals much more precise (docs/calibrate.md); tell
 * a deviation about a third of the factor's possible error. BAD_SETTING for a
 * capsule beyond the count, a factor outside [0.25, 4] or a deviation
 * outside [0.001, 1]; NON_FINITE for NaN or infinity. */
int32_t capsule_mpc_set_model_factors(capsule_mpc_t *handle, uint32_t capsule,
                                      double gain, double drag,
                                      double gain_std, double drag_std);

/* Which tier produced the last cycle's plan: CAPSULE_MPC_TIER_EXPLICIT,
 * _REFINED, or _NONE when the cycle solved nothing (before any cycle, no
 * target, terminal hold, fallback). */
int32_t capsule_mpc_last_tier(capsule_mpc_t *handle, int32_t *tier);

/* Status of the last cycle (CAPSULE_MPC_STATUS_NO_TARGET before any). */
int32_t capsule_mpc_last_status(capsule_mpc_t *handle, int32_t *status);

/* State estimate [x1, v1, x2, v2, ...] (capacity >= 2M) at the end of the
 * last actuation phase returned (its start + *samples x sample time): the
 * predicted state at the next measurement when tracking starts right after
 * the actuation. After init or reset: the rest state given there. Ideal
 * sampling: the state last fed. */
int32_t capsule_mpc_estimate(capsule_mpc_t *handle, double *state, size_t capacity);

#ifdef __cplusplus
}
#endif

#endif /* CAPSULE_MPC_H */
