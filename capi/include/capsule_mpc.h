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
 * the three constant queries. On error nothing changes and no output is
 * written. Units: SI (m, m/s, s, T/m).
 *
 * Call order:
 *   capsule_mpc_dimensions / capsule_mpc_abi_version   (check the build)
 *   capsule_mpc_init(buf, size, positions, M)
 *   capsule_mpc_set_sampling(h, mode)                  (optional, before the loop)
 *   capsule_mpc_set_target(h, target, 2M)
 *   loop: tracking phase (u = 0), then
 *         capsule_mpc_feed_tracking(h, positions, M, t, lost)
 *           (or capsule_mpc_feed_state for ideal sampling)
 *         capsule_mpc_next_actuation(h, grads, cap, &samples, &status)
 *         play grads[0..samples), one per sample time
 */
#ifndef CAPSULE_MPC_H
#define CAPSULE_MPC_H

#include <stddef.h>
#include <stdint.h>

#ifdef __cplusplus
extern "C" {
#endif

#define CAPSULE_MPC_ABI_VERSION 2u

/* Error codes. */
#define CAPSULE_MPC_OK 0
#define CAPSULE_MPC_ERR_NULL_POINTER (-1)
#define CAPSULE_MPC_ERR_BAD_SIZE (-2)
#define CAPSULE_MPC_ERR_BAD_ALIGN (-3)
#define CAPSULE_MPC_ERR_WRONG_LENGTH (-4)
#define CAPSULE_MPC_ERR_NON_FINITE (-5)
#define CAPSULE_MPC_ERR_TARGET_OUT_OF_RANGE (-6)
#define CAPSULE_MPC_ERR_BAD_MODE (-7)
#define CAPSULE_MPC_ERR_NOT_INITIALIZED (-8)
#define CAPSULE_MPC_ERR_BAD_SETTING (-9)

/* Sampling modes (capsule_mpc_set_sampling). */
#define CAPSULE_MPC_SAMPLING_IDEAL 0
#define CAPSULE_MPC_SAMPLING_CONSTANT 1
#define CAPSULE_MPC_SAMPLING_VARIABLE 2

/* Cycle status (capsule_mpc_next_actuation, capsule_mpc_last_status).
 * The plan is usable and within |u| <= u_max whatever the status. */
#define CAPSULE_MPC_STATUS_OK 0
#define CAPSULE_MPC_STATUS_FALLBACK 1             /* outside the tables: braking */
#define CAPSULE_MPC_STATUS_ITERATION_LIMIT 2      /* best feasible plan used */
#define CAPSULE_MPC_STATUS_MEASUREMENT_REJECTED 3 /* frame implausible, ignored */
#define CAPSULE_MPC_STATUS_MEASUREMENT_LOST 4     /* no frame: predicted only */
#define CAPSULE_MPC_STATUS_NO_TARGET 5            /* zero gradient */
#define CAPSULE_MPC_STATUS_REACQUIRED 6           /* estimate was wrong: restarted at this frame */
#define CAPSULE_MPC_STATUS_ABOVE_ITERATION_MAP 7  /* QP took more iterations than measured offline here */

/* Opaque controller; a handle is the buffer given to capsule_mpc_init. */
typedef struct capsule_mpc capsule_mpc_t;

uint32_t capsule_mpc_abi_version(void);

/* Bytes and alignment of the buffer capsule_mpc_init needs. */
size_t capsule_mpc_workspace_size(void);
size_t capsule_mpc_workspace_align(void);

/* Build dimensions: capsule count M, online horizon N (the largest number of
 * samples one cycle returns), plan length, sample time and gradient bound. */
int32_t capsule_mpc_dimensions(uint32_t *capsules, uint32_t *horizon, uint32_t *plan_len,
                               double *sample_time_s, double *u_max_t_per_m);

/* Builds a controller in buffer (size bytes, aligned): capsules at rest at
 * positions_m[0..n_positions), n_positions = M; constant sampling; no target. */
int32_t capsule_mpc_init(void *buffer, size_t size, const double *positions_m, size_t n_positions);

/* Restarts the estimate at rest at positions_m (n = M); keeps the target. */
int32_t capsule_mpc_reset(capsule_mpc_t *handle, const double *positions_m, size_t n);

/* Target [x1, v1, x2, v2, ...] (n = 2M, speeds 0). */
int32_t capsule_mpc_set_target(capsule_mpc_t *handle, const double *target, size_t n);

/* CAPSULE_MPC_SAMPLING_*; restarts the estimate at rest at the current
 * estimated positions (keeps the target): call before the loop. */
int32_t capsule_mpc_set_sampling(capsule_mpc_t *handle, int32_t mode);

/* One tracking frame: positions (n = M) measured at the start of the tracking
 * phase that just ended, at time t_measured_s (finite). lost != 0: no frame
 * (positions_m may be NULL). */
int32_t capsule_mpc_feed_tracking(capsule_mpc_t *handle, const double *positions_m, size_t n,
                                  double t_measured_s, int32_t lost);

/* Full state [x1, v1, x2, v2, ...] (n = 2M), for ideal sampling. */
int32_t capsule_mpc_feed_state(capsule_mpc_t *handle, const double *state, size_t n);

/* Runs one cycle on the fed frame (none fed = lost) and writes
 * gradients_t_per_m[0..min(capacity, plan_len)); play the first *samples,
 * one per sample time, from the actuation start. capacity >= horizon. */
int32_t capsule_mpc_next_actuation(capsule_mpc_t *handle, double *gradients_t_per_m, size_t capacity,
                                   uint32_t *samples, int32_t *status);

/* Status of the last cycle (CAPSULE_MPC_STATUS_NO_TARGET before any). */
int32_t capsule_mpc_last_status(capsule_mpc_t *handle, int32_t *status);

/* State estimate [x1, v1, x2, v2, ...] (capacity >= 2M). */
int32_t capsule_mpc_estimate(capsule_mpc_t *handle, double *state, size_t capacity);

#ifdef __cplusplus
}
#endif

#endif /* CAPSULE_MPC_H */
