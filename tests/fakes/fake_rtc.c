/* A fake SCANLAB RTC5/RTC6 library for tests: the DLL functions insitu calls, with the
 * vendor's C signatures, recording every call as text ("name arg arg ...") and simulating
 * a board that executes list 1 a few list commands per get_status() poll.
 *
 * Test controls (not part of the RTC API): fake_calls(), fake_marks(), fake_reset(),
 * fake_fail_after(n) (the board stops answering after n more calls: get_last_error() says 8,
 * nothing executes any more and its outputs drop), fake_set_step(n), fake_laser_enabled(),
 * fake_port(), fake_dead().
 *
 * Build: cc -shared -fPIC -o libfake_rtc.so fake_rtc.c -lpthread
 */
#include <pthread.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

typedef unsigned int UINT;

typedef struct { char *p; size_t n, cap; } text_t;
typedef struct { int op; int a, b, c; double d; } entry_t;   /* op: 1 jump, 2 mark, 3 io */

static pthread_mutex_t mu = PTHREAD_MUTEX_INITIALIZER;
static text_t calls_log, marks_log;
static entry_t list[200000];
static int list_len, exec_pos, executing, loading, step = 4;
static long ncalls, fail_after = -1;
static int dead, laser_enabled, last_error;
static UINT port;
static int px, py, pz, list_runs;

static void put(text_t *t, const char *fmt, ...) {
    char line[256];
    va_list ap;
    va_start(ap, fmt);
    int k = vsnprintf(line, sizeof line, fmt, ap);
    va_end(ap);
    if (t->n + k + 1 > t->cap) {
        t->cap = (t->cap + k + 1) * 2;
        t->p = realloc(t->p, t->cap);
    }
    memcpy(t->p + t->n, line, k + 1);
    t->n += k;
}

/* every API call: count it, maybe die, log it */
static void call(const char *fmt, ...) {
    char line[200];
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(line, sizeof line, fmt, ap);
    va_end(ap);
    ncalls++;
    if (fail_after >= 0 && ncalls > fail_after && !dead) {
        dead = 1;
        executing = 0;
        laser_enabled = 0;
        port = 0;
    }
    put(&calls_log, "%s%s\n", dead ? "!" : "", line);
}

static void add(int op, int a, int b, int c) {
    if (!loading || dead || list_len >= (int)(sizeof list / sizeof list[0])) return;
    list[list_len].op = op; list[list_len].a = a; list[list_len].b = b; list[list_len].c = c;
    list_len++;
}

static void advance(void) {
    for (int k = 0; k < step && executing; k++) {
        if (exec_pos >= list_len) { executing = 0; break; }
        entry_t *e = &list[exec_pos++];
        if (e->op == 2 && laser_enabled)
            put(&marks_log, "%d %d %d %d %d %d %d\n", list_runs, px, py, pz, e->a, e->b, e->c);
        if (e->op == 1 || e->op == 2) { px = e->a; py = e->b; pz = e->c; }
        if (e->op == 3) port = (port & ~(UINT)e->b) | ((UINT)e->a & (UINT)e->b);
    }
    if (exec_pos >= list_len) executing = 0;
}

#define LOCK pthread_mutex_lock(&mu)
#define UNLOCK pthread_mutex_unlock(&mu)

UINT init_rtc5_dll(void) { LOCK; call("init_rtc5_dll"); UNLOCK; return 0; }
UINT init_rtc6_dll(void) { LOCK; call("init_rtc6_dll"); UNLOCK; return 0; }
void free_rtc5_dll(void) { LOCK; call("free_rtc5_dll"); UNLOCK; }
void free_rtc6_dll(void) { LOCK; call("free_rtc6_dll"); UNLOCK; }
UINT select_rtc(UINT card) { LOCK; call("select_rtc %u", card); UNLOCK; return card == 1 ? 1 : 0; }
UINT load_program_file(const char *path) {
    LOCK; call("load_program_file %s", path ? path : "(null)"); UNLOCK; return 0;
}
UINT load_correction_file(const char *name, UINT no, UINT dim) {
    LOCK;
    call("load_correction_file %s %u %u", name ? name : "(null)", no, dim);
    FILE *f = name ? fopen(name, "rb") : NULL;
    UINT r = f ? (dim == 3 ? 0 : 11) : 3;     /* 3: file not found, 11: wrong dimension */
    if (f) fclose(f);
    UNLOCK;
    return r;
}
void select_cor_table(UINT a, UINT b) { LOCK; call("select_cor_table %u %u", a, b); UNLOCK; }
UINT get_last_error(void) {
    LOCK; call("get_last_error"); UINT e = dead ? 8 : last_error; UNLOCK; return e;
}
void reset_error(UINT code) { LOCK; call("reset_error %u", code); last_error &= ~code; UNLOCK; }
void set_laser_mode(UINT m) { LOCK; call("set_laser_mode %u", m); UNLOCK; }
void set_laser_control(UINT c) { LOCK; call("set_laser_control %u", c); UNLOCK; }
void set_start_list(UINT n) {
    LOCK; call("set_start_list %u", n);
    if (!dead) {
        if (executing) last_error |= 32;     /* list busy */
        else { loading = 1; list_len = 0; }
    }
    UNLOCK;
}
void set_end_of_list(void) { LOCK; call("set_end_of_list"); loading = 0; UNLOCK; }
void execute_list(UINT n) {
    LOCK; call("execute_list %u", n);
    if (!dead && n == 1) { executing = 1; exec_pos = 0; list_runs++; }
    UNLOCK;
}
void get_status(UINT *busy, UINT *pos) {
    LOCK; call("get_status");
    if (!dead) advance();
    *busy = dead ? 1 : (UINT)executing;
    *pos = (UINT)exec_pos;
    UNLOCK;
}
void stop_execution(void) { LOCK; call("stop_execution"); if (!dead) executing = 0; UNLOCK; }
void enable_laser(void) { LOCK; call("enable_laser"); if (!dead) laser_enabled = 1; UNLOCK; }
void disable_laser(void) { LOCK; call("disable_laser"); if (!dead) laser_enabled = 0; UNLOCK; }
void write_io_port_mask(UINT v, UINT m) {
    LOCK; call("write_io_port_mask %u %u", v, m); if (!dead) port = (port & ~m) | (v & m); UNLOCK;
}
void write_io_port_mask_list(UINT v, UINT m) {
    LOCK; call("write_io_port_mask_list %u %u", v, m); add(3, (int)v, (int)m, 0); UNLOCK;
}
void write_da_1_list(UINT v) { LOCK; call("write_da_1_list %u", v); add(4, (int)v, 0, 0); UNLOCK; }
void set_laser_pulses(UINT half, UINT len) {
    LOCK; call("set_laser_pulses %u %u", half, len); add(5, (int)half, (int)len, 0); UNLOCK;
}
void set_laser_delays(int on, UINT off) {
    LOCK; call("set_laser_delays %d %u", on, off); add(6, on, (int)off, 0); UNLOCK;
}
void set_scanner_delays(UINT j, UINT m, UINT p) {
    LOCK; call("set_scanner_delays %u %u %u", j, m, p); add(7, (int)j, (int)m, (int)p); UNLOCK;
}
void set_wobbel(UINT tr, UINT lo, double f) {
    LOCK; call("set_wobbel %u %u %.3f", tr, lo, f); add(10, (int)tr, (int)lo, (int)f); UNLOCK;
}
void set_jump_speed(double v) { LOCK; call("set_jump_speed %.6f", v); add(8, 0, 0, 0); UNLOCK; }
void set_mark_speed(double v) { LOCK; call("set_mark_speed %.6f", v); add(9, 0, 0, 0); UNLOCK; }
void jump_abs_3d(int x, int y, int z) {
    LOCK; call("jump_abs_3d %d %d %d", x, y, z); add(1, x, y, z); UNLOCK;
}
void mark_abs_3d(int x, int y, int z) {
    LOCK; call("mark_abs_3d %d %d %d", x, y, z); add(2, x, y, z); UNLOCK;
}

/* ---- test controls ---- */
const char *fake_calls(void) { return calls_log.p ? calls_log.p : ""; }
const char *fake_marks(void) { return marks_log.p ? marks_log.p : ""; }
void fake_reset(void) {
    LOCK;
    calls_log.n = marks_log.n = 0;
    if (calls_log.p) calls_log.p[0] = 0;
    if (marks_log.p) marks_log.p[0] = 0;
    list_len = exec_pos = executing = loading = 0;
    ncalls = 0; fail_after = -1; dead = laser_enabled = last_error = 0; port = 0;
    px = py = pz = 0; list_runs = 0; step = 4;
    UNLOCK;
}
void fake_fail_after(long n) { LOCK; fail_after = n < 0 ? -1 : ncalls + n; UNLOCK; }
void fake_set_step(int n) { LOCK; step = n > 0 ? n : 1; UNLOCK; }
int fake_laser_enabled(void) { return laser_enabled; }
UINT fake_port(void) { return port; }
int fake_dead(void) { return dead; }
