/*
 * duffid_cosim_loop.c - the macro steps of duffid's co-simulation orchestrator in C.
 *
 * duffid.cosim.runner prepares, for a system of C FMUs, the same operations its Python loop
 * executes every macro step (FMI set calls, doStep calls, get calls, conversions, the input
 * table rows and the recorded rows) as flat arrays of the structures below, and calls
 * duffid_cosim_run for a range of macro steps. The C loop performs exactly those
 * operations in the same order on the same buffers: the results equal the Python loop's bit
 * for bit (only values are copied; no arithmetic is done on them).
 *
 * A doStep that does not simply succeed (status above Warning, an FMI 3 request to terminate, or
 * eventHandlingNeeded of an FMU that uses Event Mode) is handed to the caller's callback, which
 * answers: DUFFID_STEP_ENDED = the FMU asked to end the simulation after this macro step (the step
 * is completed and recorded, then the loop returns DUFFID_LOOP_ENDED), DUFFID_STEP_EVENT_HANDLED =
 * the caller ran the FMU's Event Mode (continue), anything else = abort now (DUFFID_LOOP_ABORTED).
 *
 * C99, no allocation, no global or static mutable state. The structures and return codes are
 * in duffid_cosim_loop.h (shared with the container FMU runtime, fmus/container).
 */
#include <string.h>

#include "duffid_cosim_loop.h"

typedef int (*call4_t)(void *, const unsigned int *, size_t, void *);
typedef int (*call5_t)(void *, const unsigned int *, size_t, void *, size_t);
typedef int (*fmi2_do_step_t)(void *, double, double, int);
typedef int (*fmi3_do_step_t)(void *, double, double, _Bool, _Bool *, _Bool *, _Bool *, double *);

static void convert_values(char *dst, const char *src, size_t n, size_t itemsize, int convert)
{
    size_t i;
    if (convert == DUFFID_INT32_TO_BOOL) {
        for (i = 0; i < n; i++) {
            int32_t v;
            memcpy(&v, src + i * 4, 4);
            ((_Bool *)dst)[i] = v != 0;
        }
    } else if (convert == DUFFID_BOOL_TO_INT32) {
        for (i = 0; i < n; i++) {
            int32_t v = ((const _Bool *)src)[i] ? 1 : 0;
            memcpy(dst + i * 4, &v, 4);
        }
    } else if (convert == DUFFID_INT64_TO_INT32) {
        for (i = 0; i < n; i++) {
            int64_t v;
            int32_t w;
            memcpy(&v, src + i * 8, 8);
            w = (int32_t)v;
            memcpy(dst + i * 4, &w, 4);
        }
    } else if (convert == DUFFID_INT32_TO_INT64) {
        for (i = 0; i < n; i++) {
            int32_t v;
            int64_t w;
            memcpy(&v, src + i * 4, 4);
            w = v;
            memcpy(dst + i * 8, &w, 8);
        }
    } else {
        memcpy(dst, src, n * itemsize);
    }
}

/* Bytes per converted value written by `convert` (itemsize: bytes per source value). */
static size_t converted_size(int convert, size_t itemsize)
{
    switch (convert) {
    case DUFFID_INT32_TO_BOOL: return 1;
    case DUFFID_BOOL_TO_INT32: case DUFFID_INT64_TO_INT32: return 4;
    case DUFFID_INT32_TO_INT64: return 8;
    default: return itemsize;
    }
}

static void gather(char *dst, const char *src, const intptr_t *index, size_t n, size_t itemsize, int convert)
{
    size_t i;
    size_t out = converted_size(convert, itemsize);
    for (i = 0; i < n; i++)
        convert_values(dst + i * out, src + (size_t)index[i] * itemsize, 1, itemsize, convert);
}

static int io_call(const duffid_io_op *op)
{
    const size_t n_values = op->n_values ? op->n_values : op->n;
    if (op->call != NULL) return op->call(op->context);
    if (op->gather_index != NULL)
        gather((char *)op->value, op->gather_source, op->gather_index, n_values, op->itemsize, op->convert);
    if (op->fmi3)
        return ((call5_t)op->function)(op->instance, op->vr, op->n, op->value, n_values);
    return ((call4_t)op->function)(op->instance, op->vr, op->n, op->value);
}

static void move(const duffid_move *m, long row)
{
    char *dst = m->destination + row * m->destination_stride;
    const char *src = m->source + row * m->source_stride;
    if (m->call != NULL)
        m->call(row);
    else if (m->index != NULL)
        gather(dst, src, m->index, m->n, m->itemsize, m->convert);
    else
        convert_values(dst, src, m->n, m->itemsize, m->convert);
}

/* See duffid_cosim_loop.h. */
int duffid_cosim_run(const double *grid, long start, long stop, double h, const duffid_stage *stages,
                     int n_stages, const duffid_io_op *sets, const duffid_step_op *steps, const duffid_io_op *gets,
                     const duffid_move *posts, const duffid_move *moves, int n_moves,
                     duffid_step_callback on_step, long *failed_step, int *failed_op, int *failed_status)
{
    long k;
    for (k = start; k < stop; k++) {
        const double t = grid[k];
        int ending = 0, s, i, status;
        *failed_step = k;
        for (s = 0; s < n_stages; s++) {
            const duffid_stage *stage = &stages[s];
            for (i = stage->set_lo; i < stage->set_hi; i++) {
                status = io_call(&sets[i]);
                if (status > FMI_WARNING) {
                    *failed_op = i;
                    *failed_status = status;
                    return DUFFID_LOOP_SET_FAILED;
                }
            }
            for (i = stage->step_lo; i < stage->step_hi; i++) {
                const duffid_step_op *op = &steps[i];
                int terminate, event;
                if (op->fmi3) {
                    status = ((fmi3_do_step_t)op->function)(op->instance, t, h, 1, op->event_handling_needed,
                                                           op->terminate, op->early_return,
                                                           op->last_successful_time);
                    terminate = *op->terminate;
                    event = op->event_mode && *op->event_handling_needed;
                } else {
                    status = ((fmi2_do_step_t)op->function)(op->instance, t, h, 1);
                    terminate = event = 0;
                }
                if (status > FMI_WARNING || terminate || event) {
                    int answer = on_step(i, status, k);
                    if (answer == DUFFID_STEP_ENDED) {
                        ending = 1;
                    } else if (answer != DUFFID_STEP_EVENT_HANDLED) {
                        *failed_op = i;
                        *failed_status = status;
                        return DUFFID_LOOP_ABORTED;
                    }
                }
            }
            for (i = stage->get_lo; i < stage->get_hi; i++) {
                status = io_call(&gets[i]);
                if (status > FMI_WARNING) {
                    *failed_op = i;
                    *failed_status = status;
                    return DUFFID_LOOP_GET_FAILED;
                }
            }
            for (i = stage->post_lo; i < stage->post_hi; i++)
                move(&posts[i], 0);
        }
        for (i = 0; i < n_moves; i++)
            move(&moves[i], k + 1);
        if (ending)
            return DUFFID_LOOP_ENDED;
    }
    *failed_step = stop;
    return DUFFID_LOOP_DONE;
}
