/*
 * duffid_cosim_loop.h - the operations of a macro step and duffid_cosim_run, the loop that
 * executes them (duffid_cosim_loop.c). Shared by the orchestrator's compiled loop
 * (duffid.cosim.compiled_loop, through ctypes: keep its structures in step) and the
 * container FMU runtime (fmus/container), which builds the same operations in C.
 */
#ifndef DUFFID_COSIM_LOOP_H
#define DUFFID_COSIM_LOOP_H

#include <stddef.h>
#include <stdint.h>

#define DUFFID_LOOP_DONE 0
#define DUFFID_LOOP_SET_FAILED 1
#define DUFFID_LOOP_GET_FAILED 2
#define DUFFID_LOOP_ABORTED 3
#define DUFFID_LOOP_ENDED 4

/* Value conversions of a gather or a move. */
#define DUFFID_COPY 0          /* same type: bytes */
#define DUFFID_INT32_TO_BOOL 1 /* a 4-byte integer buffer to 1-byte fmi3Boolean */
#define DUFFID_BOOL_TO_INT32 2 /* 1-byte fmi3Boolean to a 4-byte integer buffer */
#define DUFFID_INT64_TO_INT32 3 /* an 8-byte integer buffer to 4-byte integers (FMI 2 Enumeration) */
#define DUFFID_INT32_TO_INT64 4 /* 4-byte integers (FMI 2 Enumeration) to an 8-byte integer buffer */

#define FMI_WARNING 1

/* Any function pointer (the FMI functions are cast to their own types before the call). */
typedef void (*duffid_function)(void);

/* An FMI get or set call: function(instance, vr, n, value[, n]) (FMI 3 repeats n as nValues).
 * With gather_index != NULL the values are first gathered into value from
 * gather_source[gather_index[i]] (the Python loop's np.take). */
typedef struct {
    duffid_function function;
    void *instance;
    const unsigned int *vr;
    size_t n;
    void *value;
    int fmi3;
    int convert;
    const char *gather_source;
    const intptr_t *gather_index;
    size_t itemsize; /* bytes per value of gather_source */
    size_t n_values; /* FMI 3: values of the n variables (arrays have several); 0: n (scalars) */
    int (*call)(void *context); /* non-NULL: the caller's own operation instead of the above (String
                                 * and Binary values, which the caller copies), given `context`; it
                                 * returns an FMI status */
    void *context;
} duffid_io_op;

/* A doStep call; FMI 3 writes its three flags and the last successful time. */
typedef struct {
    duffid_function function;
    void *instance;
    int fmi3;
    _Bool *event_handling_needed;
    _Bool *terminate;
    _Bool *early_return;
    double *last_successful_time;
    int event_mode; /* FMI 3 with eventModeUsed: eventHandlingNeeded goes to the callback */
} duffid_step_op;

/* A copy of n values for row r (= k + 1 after macro step k): from source + r * source_stride
 * (at index[i] when index != NULL) to destination + r * destination_stride. Tables are moves
 * with destination_stride 0, recorded rows moves with source_stride 0, FMI 3 Boolean outputs
 * moves with both 0. */
typedef struct {
    char *destination;
    const char *source;
    const intptr_t *index;
    size_t n;
    size_t itemsize; /* bytes per value of source */
    ptrdiff_t destination_stride, source_stride;
    int convert;
    int (*call)(long row); /* non-NULL: the caller's own copy for row `row` instead of the above */
} duffid_move;

/* One stage of a macro step: sets, doSteps, gets and conversions [lo, hi) (Jacobi: one stage
 * of everything; Gauss-Seidel: one stage per component in the stepping order). */
typedef struct {
    int set_lo, set_hi, step_lo, step_hi, get_lo, get_hi, post_lo, post_hi;
} duffid_stage;

/* What the callback answers about a doStep it was handed: the FMU asked to end the simulation
 * (complete the macro step, then stop), the caller handled the FMU's Event Mode (continue);
 * anything else aborts. */
#define DUFFID_STEP_ENDED 0
#define DUFFID_STEP_ABORT 1
#define DUFFID_STEP_EVENT_HANDLED 2

typedef int (*duffid_step_callback)(int step_op, int status, long step);

/*
 * Macro steps k = start .. stop-1 on grid (t_k = grid[k], step h): per stage its sets, doSteps,
 * gets and conversions, then the moves (input table rows, recorded rows) for row k + 1.
 * Returns DUFFID_LOOP_*; *failed_step = the macro step being executed, *failed_op = the op
 * index within its kind, *failed_status = the FMI status (failures only).
 */
int duffid_cosim_run(const double *grid, long start, long stop, double h, const duffid_stage *stages,
                     int n_stages, const duffid_io_op *sets, const duffid_step_op *steps, const duffid_io_op *gets,
                     const duffid_move *posts, const duffid_move *moves, int n_moves,
                     duffid_step_callback on_step, long *failed_step, int *failed_op, int *failed_status);

#endif
