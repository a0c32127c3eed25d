/*
 * Closed loop through the C ABI of generated/sindy_m100 (uavgen --c-api; docs/c-api.md).
 *
 * The MPC tracks a piecewise-linear waypoint reference for 900 samples (30 s at 30 Hz), with the
 * model itself as the plant (sindy_m100_discrete_dynamics). The loop follows the real-time
 * iteration timeline of a flight controller:
 *
 *     feedback(x) -> apply u -> shift -> prepare(next reference window) -> wait for the next x
 *
 * Output, one line per sample, inputs printed with %.17g so that they round-trip exactly:
 *
 *     step <k> <status> <qp iterations> <u_vz> <u_roll> <u_pitch> <u_yaw_rate>
 *
 * tests/c_abi.rs runs the same loop through the Rust API and compares the inputs (to 1e-12).
 * Before the loop, the ABI's refusals (NULL, uninitialised storage, too small, overlap, no
 * solution yet) are checked; the program exits with status 1 if one does not behave. Then init runs
 * on a thread with a 16 KiB stack (glibc's smallest) and prepare + feedback + shift on one with
 * 32 KiB: the solver lives in the caller's storage, not on the stack (an overflow kills the process).
 */
#include <math.h>
#include <pthread.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "sindy_m100.h"

#define NX SINDY_M100_NX
#define NU SINDY_M100_NU
#define N SINDY_M100_N
#define STEPS 900
/* Samples between waypoints, and of the ramp from one to the next. */
#define SEGMENT 150
#define RAMP 60

typedef sindy_m100_real real;

/* The solver's storage: a zero-filled static, owned by this program (no heap anywhere). */
static sindy_m100_storage storage;

/* Waypoints (x, y, z, yaw); the reference ramps linearly to waypoint j + 1 over the first RAMP
 * samples of segment j, then holds. Plain arithmetic, evaluated exactly alike in tests/c_abi.rs. */
static const real WAYPOINTS[][4] = {
    {0.0, 0.0, 0.0, 0.0},  {1.0, 0.0, 0.5, 0.0},   {1.0, 1.0, 0.5, 0.5},  {0.0, 1.0, 1.0, 1.0},
    {-1.0, 0.0, 0.5, 0.5}, {-0.5, -0.5, 0.0, 0.0}, {0.0, 0.0, 0.0, 0.0},  {0.0, 0.0, 0.0, 0.0},
};
static const int POSITION_STATES[4] = {0, 1, 2, 5}; /* x, y, z, yaw */

static void reference_at(int k, real r[NX]) {
    int segment = k / SEGMENT;
    int into = k % SEGMENT;
    real s = (real)(into < RAMP ? into : RAMP) / (real)RAMP;
    if (segment > 6) {
        segment = 6;
        s = 1.0;
    }
    memset(r, 0, sizeof(real) * NX);
    for (int i = 0; i < 4; i++) {
        real a = WAYPOINTS[segment][i], b = WAYPOINTS[segment + 1][i];
        r[POSITION_STATES[i]] = a + (b - a) * s;
    }
}

static void window_at(int k, real window[(N + 1) * NX]) {
    for (int j = 0; j <= N; j++) {
        reference_at(k + j, &window[j * NX]);
    }
}

static int failures = 0;

static void expect(const char *what, sindy_m100_status got, sindy_m100_status want) {
    if (got != want) {
        fprintf(stderr, "abi check failed: %s returned %d, expected %d\n", what, (int)got, (int)want);
        failures++;
    }
}

/* The refusals of the ABI: each must return its code and change nothing. */
static void abi_checks(void) {
    real x0[NX] = {0};
    real u[NU] = {0};
    real window[(N + 1) * NX];
    uint32_t iterations = 0;
    window_at(0, window);

    if (sindy_m100_storage_size() > sizeof(storage) || sindy_m100_storage_align() > SINDY_M100_STORAGE_ALIGN) {
        fprintf(stderr, "abi check failed: storage %zu bytes / align %zu exceed the header's %zu / %d\n",
                sindy_m100_storage_size(), sindy_m100_storage_align(), sizeof(storage), SINDY_M100_STORAGE_ALIGN);
        failures++;
    }
    /* The static storage is zero: not initialised yet. */
    expect("prepare before init", sindy_m100_prepare(&storage, window), SINDY_M100_NOT_INITIALISED);
    expect("shift before init", sindy_m100_shift(&storage), SINDY_M100_NOT_INITIALISED);
    expect("init(NULL)", sindy_m100_init(NULL, sizeof(storage), x0, u), SINDY_M100_NULL_POINTER);
    expect("init(x0 = NULL)", sindy_m100_init(&storage, sizeof(storage), NULL, u), SINDY_M100_NULL_POINTER);
    expect("init(size 64)", sindy_m100_init(&storage, 64, x0, u), SINDY_M100_STORAGE_TOO_SMALL);
    expect("last_status before init", sindy_m100_last_status(&storage), SINDY_M100_NOT_INITIALISED);
    expect("init", sindy_m100_init(&storage, sizeof(storage), x0, u), SINDY_M100_OK);
    expect("last_status before feedback", sindy_m100_last_status(&storage), SINDY_M100_NO_SOLUTION);
    expect("qp_iterations before feedback", sindy_m100_qp_iterations(&storage, &iterations),
           SINDY_M100_NO_SOLUTION);
    expect("prepare(NULL)", sindy_m100_prepare(&storage, NULL), SINDY_M100_NULL_POINTER);
    /* An output inside the storage would corrupt the solver: refused. */
    expect("feedback(u0 in the storage)",
           sindy_m100_feedback(&storage, x0, (real *)(void *)&storage.bytes[sizeof(storage) / 2]),
           SINDY_M100_OVERLAP);
    expect("feedback(u0 = NULL)", sindy_m100_feedback(&storage, x0, NULL), SINDY_M100_NULL_POINTER);
    x0[3] = NAN;
    expect("solve(NaN state)", sindy_m100_solve(&storage, x0, window, u), SINDY_M100_INVALID_INPUT);
    real u_min[NU] = SINDY_M100_U_MIN, u_max[NU] = SINDY_M100_U_MAX;
    for (int i = 0; i < NU; i++) {
        if (!(u[i] >= u_min[i] && u[i] <= u_max[i])) {
            fprintf(stderr, "abi check failed: u[%d] = %g after INVALID_INPUT is not within its bounds\n", i, u[i]);
            failures++;
        }
    }
    expect("discrete_dynamics(x_next = NULL)", sindy_m100_discrete_dynamics(x0, u, NULL), SINDY_M100_NULL_POINTER);
}

/* Small-stack threads: init with 16 KiB, three prepare + feedback + shift with 32 KiB. */
static void *init_thread(void *arg) {
    (void)arg;
    real x0[NX] = {0}, u[NU] = {0};
    expect("init on a 16 KiB stack", sindy_m100_init(&storage, sizeof(storage), x0, u), SINDY_M100_OK);
    return NULL;
}

static real small_stack_window[(N + 1) * NX];

static void *step_thread(void *arg) {
    (void)arg;
    real x0[NX] = {0}, u[NU];
    for (int k = 0; k < 3; k++) {
        expect("prepare on a 32 KiB stack", sindy_m100_prepare(&storage, small_stack_window), SINDY_M100_OK);
        expect("feedback on a 32 KiB stack", sindy_m100_feedback(&storage, x0, u), SINDY_M100_OK);
        expect("shift on a 32 KiB stack", sindy_m100_shift(&storage), SINDY_M100_OK);
    }
    return NULL;
}

static void on_stack(size_t bytes, void *(*f)(void *)) {
    pthread_attr_t attr;
    pthread_t thread;
    if (pthread_attr_init(&attr) != 0 || pthread_attr_setstacksize(&attr, bytes) != 0 ||
        pthread_create(&thread, &attr, f, NULL) != 0 || pthread_join(thread, NULL) != 0) {
        fprintf(stderr, "small-stack check: cannot run a thread with %zu bytes of stack\n", bytes);
        failures++;
    }
    pthread_attr_destroy(&attr);
}

static void small_stack_checks(void) {
    window_at(0, small_stack_window);
    on_stack(16 * 1024, init_thread);
    on_stack(32 * 1024, step_thread);
}

int main(void) {
    abi_checks();
    small_stack_checks();
    if (failures) {
        return 1;
    }
    printf("abi-checks ok (init on 16 KiB, prepare + feedback on 32 KiB threads): storage %zu of %d bytes, align %zu\n", sindy_m100_storage_size(),
           SINDY_M100_STORAGE_SIZE, sindy_m100_storage_align());

    /* Start 0.5 m off the first waypoint, at rest. */
    real x[NX] = {0};
    x[0] = -0.5;
    x[1] = 0.3;
    x[2] = -0.2;
    real u[NU] = {0};
    real window[(N + 1) * NX];
    sindy_m100_status status = sindy_m100_init(&storage, sizeof(storage), x, u);
    window_at(0, window);
    if (status == SINDY_M100_OK) {
        status = sindy_m100_prepare(&storage, window);
    }
    if (status < 0) {
        fprintf(stderr, "init/prepare: status %d\n", (int)status);
        return 1;
    }
    for (int k = 0; k < STEPS; k++) {
        uint32_t iterations = 0;
        status = sindy_m100_feedback(&storage, x, u);
        if (status < 0 || sindy_m100_qp_iterations(&storage, &iterations) != SINDY_M100_OK) {
            fprintf(stderr, "step %d: feedback status %d\n", k, (int)status);
            return 1;
        }
        printf("step %d %d %u %.17g %.17g %.17g %.17g\n", k, (int)status, (unsigned)iterations, u[0], u[1], u[2],
               u[3]);
        /* The plant: the model itself. */
        real next[NX];
        if (sindy_m100_discrete_dynamics(x, u, next) != SINDY_M100_OK) {
            return 1;
        }
        memcpy(x, next, sizeof(x));
        window_at(k + 1, window);
        if (sindy_m100_shift(&storage) != SINDY_M100_OK || sindy_m100_prepare(&storage, window) < 0) {
            return 1;
        }
    }
    real r[NX];
    reference_at(STEPS, r);
    printf("final position error %.6f m\n",
           sqrt((x[0] - r[0]) * (x[0] - r[0]) + (x[1] - r[1]) * (x[1] - r[1]) + (x[2] - r[2]) * (x[2] - r[2])));
    return 0;
}
