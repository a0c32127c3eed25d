/*
 * Link check for a Cortex-M flight controller: a freestanding C "firmware" (no libc, no startup
 * code) that calls the C ABI of generated/sindy_m100, compiled with arm-none-eabi-gcc for the
 * hard-float EABI that PX4 and ArduPilot use and linked against libsindy_m100_capi.a built for
 * thumbv7em-none-eabihf. `make -C examples/c cortex-m` (scripts/test.sh, when arm-none-eabi-gcc is
 * installed) builds it; it is linked, not run (no board or emulator here). It proves that the
 * library resolves every symbol it needs (memcpy/memset come from Rust's compiler-builtins, no libc)
 * and that the float ABIs agree (the linker refuses to mix hard-float and soft-float objects).
 */
#include "sindy_m100.h"

/* The solver's storage: zero-filled .bss, as on a flight controller. */
static sindy_m100_storage storage;

/* What a debugger would read. */
volatile sindy_m100_real telemetry_u[SINDY_M100_NU];
volatile int32_t telemetry_status;

void reset_handler(void) {
    sindy_m100_real x[SINDY_M100_NX] = {0};
    sindy_m100_real u[SINDY_M100_NU] = {0};
    sindy_m100_real window[(SINDY_M100_N + 1) * SINDY_M100_NX] = {0};
    for (int k = 0; k <= SINDY_M100_N; k++) {
        window[k * SINDY_M100_NX + 2] = 1.0; /* 1 m up */
    }
    telemetry_status = sindy_m100_init(&storage, sizeof storage, x, u);
    sindy_m100_prepare(&storage, window);
    for (;;) {
        telemetry_status = sindy_m100_feedback(&storage, x, u);
        for (int i = 0; i < SINDY_M100_NU; i++) {
            telemetry_u[i] = u[i];
        }
        sindy_m100_real next[SINDY_M100_NX];
        sindy_m100_discrete_dynamics(x, u, next);
        for (int i = 0; i < SINDY_M100_NX; i++) {
            x[i] = next[i];
        }
        sindy_m100_shift(&storage);
        sindy_m100_prepare(&storage, window);
    }
}
