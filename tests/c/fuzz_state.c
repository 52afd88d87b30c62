/* Fuzz test of an FMU's serialized state: corrupted states must never hurt the host.
 *
 * Loads a co-simulation FMU's binary (dlopen), runs it over realistic inputs, serializes its
 * state and then, case after case, deserializes and sets a corrupted copy:
 *
 *   random         1-8 random bytes at random offsets changed (seeded PRNG), checksum left as
 *                  it is: the corruption a disk or a network makes;
 *   random-sealed  the same (outside the checksum field), with the checksum recomputed
 *                  afterwards, so the corruption reaches the FMU's identity and invariant
 *                  checks behind the checksum;
 *   sweep          at every 4-byte-aligned offset, each int32 of SWEEP_VALUES (counts, indices,
 *                  sizes and the upper words of NaN/Inf/1.0 doubles) written, checksum resealed.
 *
 * A sweep case whose bytes equal the genuine ones after resealing (a write into the checksum
 * field, or of the value already there) is skipped. Each case ends in one of:
 *
 *   rejected       deserialize or set returned Error with a logged error message, and the
 *                  instance is as it was: its outputs right after and after each following
 *                  step equal, bit for bit, those of an instance never given a corrupted state;
 *   accepted       the state was taken: the outputs right after it and the following steps
 *                  (reading the outputs after each) either return OK with every output
 *                  in its declared range (or the same outputs as the genuine state), or refuse
 *                  (Error / Discard with a logged message): consistent; anything else
 *                  (an OK step with an output out of range, a refusal without a message):
 *                  inconsistent;
 *   crash          the process died on a signal or a sanitizer report (ASan, UBSan, LSan:
 *                  the exit code EXIT_SANITIZER set by the *_default_options below);
 *   hang           the case did not finish within the time limit (alarm()).
 *
 * Cases run in a child process; when it dies, the parent counts the case and starts a new
 * child at the next case (each case's corruption depends only on the seed and its index).
 *
 *   fuzz_state <binary> <spec> [--fmi 2|3] [--mode random|random-sealed|sweep] [--cases N]
 *              [--seed S] [--timeout SECONDS]
 *
 * --cases: the random modes run N cases (default 1000); the sweep runs every (offset, value)
 * pair when N is 0 or at least their number, else N cases that visit every offset (when N is at
 * least the number of offsets) with the values rotating (see sweep_case).
 *
 * The spec file (written by tests/test_fmu_state_fuzz.py from modelDescription.xml):
 *   identifier <modelIdentifier>
 *   token <guid / instantiationToken>
 *   dt <communication step size>
 *   warmup <K>                      steps before the state is saved
 *   steps <M>                       steps after each case
 *   param <vr> <R|I|B> <value>      set before initialisation
 *   input <vr> <R|I|B>              set before every step, from the rows (in this order)
 *   output <vr> <R|I|B> <lo> <hi> <nan_ok> <name>   in [lo, hi] (or NaN if nan_ok), read
 *                                   right after the state is set and after every step
 *   row <value> ...                 one per step (K + M rows at least)
 *
 * Output: one line per failing case (up to 20 crashes and hangs), then one line
 *   RESULT fmi= mode= state_bytes= cases= rejected= accepted_consistent= accepted_inconsistent=
 *          crashes= hangs= sanitizer= skipped= rejected_unchanged= rejected_changed=
 *          rejected_silent= accepted_same= accepted_different= accepted_refused=
 * (crashes: signals and sanitizer reports, sanitizer: the latter; rejected = unchanged +
 * changed + silent; accepted_consistent = same + different + refused: outputs equal to the
 * untouched instance's, different but in range, a step refused with a logged message).
 * Exit status 0 (whatever the counts; the test judges them), 2 on a setup error.
 *
 * Build (the FMU's sources are compiled with the same sanitizer flags):
 *   cc -std=gnu99 -g -O1 -fsanitize=address,undefined,float-cast-overflow -fno-sanitize-recover=all
 *      -I<fmpy>/c-code -Ifmus/common tests/c/fuzz_state.c -o fuzz_state -ldl -lm
 */
#define _GNU_SOURCE
#include <dlfcn.h>
#include <errno.h>
#include <math.h>
#include <signal.h>
#include <stdarg.h>
#include <stdbool.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/types.h>
#include <sys/wait.h>
#include <unistd.h>

#include "fmi2Functions.h"
#include "fmi3FunctionTypes.h"
#include "fmu_instance.h" /* SNAPSHOT_CHECKSUM_OFFSET, FMU_STATE_CHECKSUM_SEED: the state's checksum */

/* Exit codes of a child: a sanitizer report (see the *_default_options below), a setup error. */
#define EXIT_SANITIZER 86
#define EXIT_SETUP 3
#define MAX_VARS 256
#define MAX_REPORTED 20

/* Sanitizer defaults: a report ends the child with EXIT_SANITIZER (the parent counts it). */
const char *__asan_default_options(void);
const char *__ubsan_default_options(void);
const char *__asan_default_options(void) { return "exitcode=86:detect_leaks=1:allocator_may_return_null=1"; }
const char *__ubsan_default_options(void) { return "exitcode=86:print_stacktrace=1:halt_on_error=1"; }

/* ------------------------------------------------------------------ spec */

typedef struct {
    unsigned vr;
    char type; /* 'R', 'I', 'B' */
    double value, lo, hi;
    int nan_ok;
    char name[64];
} Var;

typedef struct {
    char identifier[256], token[256];
    double dt;
    int warmup, steps;
    Var params[MAX_VARS], inputs[MAX_VARS], outputs[MAX_VARS];
    int n_params, n_inputs, n_outputs;
    double *rows; /* n_rows x n_inputs */
    int n_rows;
} Spec;

static void die(const char *fmt, ...)
{
    va_list args;
    va_start(args, fmt);
    fprintf(stderr, "fuzz_state: ");
    vfprintf(stderr, fmt, args);
    va_end(args);
    fputc('\n', stderr);
    exit(2);
}

static char read_type(const char *word, const char *path)
{
    if (strcmp(word, "R") != 0 && strcmp(word, "I") != 0 && strcmp(word, "B") != 0)
        die("%s: variable type %s is not R, I or B", path, word);
    return word[0];
}

/* A number that is the whole word (strtod's syntax: also nan, inf, -inf). */
static double number(const char *word, const char *path)
{
    char *end;
    double value = strtod(word, &end);
    if (end == word || *end != '\0') die("%s: %s is not a number", path, word);
    return value;
}

static void read_spec(const char *path, Spec *spec)
{
    FILE *file = fopen(path, "r");
    char line[65536], word[64], type[8];
    int capacity = 0;
    if (file == NULL) die("cannot open the spec %s: %s", path, strerror(errno));
    memset(spec, 0, sizeof *spec);
    while (fgets(line, sizeof line, file) != NULL) {
        Var *v;
        int used;
        if (sscanf(line, "%63s%n", word, &used) != 1 || word[0] == '#') continue;
        if (strcmp(word, "identifier") == 0) {
            if (sscanf(line + used, "%255s", spec->identifier) != 1) die("%s: bad line %s", path, line);
        } else if (strcmp(word, "token") == 0) {
            if (sscanf(line + used, "%255s", spec->token) != 1) die("%s: bad line %s", path, line);
        } else if (strcmp(word, "dt") == 0) {
            spec->dt = strtod(line + used, NULL);
        } else if (strcmp(word, "warmup") == 0) {
            spec->warmup = atoi(line + used);
        } else if (strcmp(word, "steps") == 0) {
            spec->steps = atoi(line + used);
        } else if (strcmp(word, "param") == 0 || strcmp(word, "input") == 0 || strcmp(word, "output") == 0) {
            int *n = word[0] == 'p' ? &spec->n_params : word[0] == 'i' ? &spec->n_inputs : &spec->n_outputs;
            Var *list = word[0] == 'p' ? spec->params : word[0] == 'i' ? spec->inputs : spec->outputs;
            char lo[64] = "-inf", hi[64] = "inf";
            if (*n >= MAX_VARS) die("%s: more than %d %s lines", path, MAX_VARS, word);
            v = &list[(*n)++];
            memset(v, 0, sizeof *v);
            if (word[0] == 'p') {
                char value[64];
                if (sscanf(line + used, "%u %7s %63s", &v->vr, type, value) != 3) die("%s: bad line %s", path, line);
                v->value = number(value, path);
            } else if (word[0] == 'i') {
                if (sscanf(line + used, "%u %7s", &v->vr, type) != 2) die("%s: bad line %s", path, line);
            } else if (sscanf(line + used, "%u %7s %63s %63s %d %63s", &v->vr, type, lo, hi, &v->nan_ok, v->name) !=
                       6) {
                die("%s: bad line %s", path, line);
            }
            v->type = read_type(type, path);
            v->lo = number(lo, path);
            v->hi = number(hi, path);
        } else if (strcmp(word, "row") == 0) {
            char *p = line + used, *end;
            int i;
            if (spec->n_rows == capacity) {
                capacity = capacity ? 2 * capacity : 1024;
                spec->rows = (double *)realloc(spec->rows, (size_t)capacity * (size_t)(spec->n_inputs + 1) *
                                                               sizeof(double));
                if (spec->rows == NULL) die("out of memory");
            }
            for (i = 0; i < spec->n_inputs; i++) {
                spec->rows[spec->n_rows * spec->n_inputs + i] = strtod(p, &end);
                if (end == p || (*end != ' ' && *end != '\t' && *end != '\n' && *end != '\0')) die("%s: row %d has fewer than %d numbers", path, spec->n_rows, spec->n_inputs);
                p = end;
            }
            spec->n_rows++;
        } else {
            die("%s: unknown line %s", path, line);
        }
    }
    fclose(file);
    if (spec->identifier[0] == '\0' || spec->token[0] == '\0' || !(spec->dt > 0.0) || spec->warmup < 1 ||
        spec->steps < 1 || spec->n_rows < spec->warmup + spec->steps)
        die("%s: needs identifier, token, dt > 0, warmup >= 1, steps >= 1 and warmup + steps rows", path);
}

/* ------------------------------------------------------------------ the FMU through FMI 2 or 3 */

typedef struct {
    int fmi;
    void *lib;
    /* FMI 2 */
    fmi2InstantiateTYPE *i2;
    fmi2FreeInstanceTYPE *free2;
    fmi2SetupExperimentTYPE *setup2;
    fmi2EnterInitializationModeTYPE *enter2;
    fmi2ExitInitializationModeTYPE *exit2;
    fmi2SetRealTYPE *setr2;
    fmi2SetIntegerTYPE *seti2;
    fmi2SetBooleanTYPE *setb2;
    fmi2GetRealTYPE *getr2;
    fmi2GetIntegerTYPE *geti2;
    fmi2GetBooleanTYPE *getb2;
    fmi2DoStepTYPE *step2;
    fmi2GetFMUstateTYPE *gets2;
    fmi2SetFMUstateTYPE *sets2;
    fmi2FreeFMUstateTYPE *frees2;
    fmi2SerializedFMUstateSizeTYPE *size2;
    fmi2SerializeFMUstateTYPE *ser2;
    fmi2DeSerializeFMUstateTYPE *deser2;
    /* FMI 3 */
    fmi3InstantiateCoSimulationTYPE *i3;
    fmi3FreeInstanceTYPE *free3;
    fmi3EnterInitializationModeTYPE *enter3;
    fmi3ExitInitializationModeTYPE *exit3;
    fmi3SetFloat64TYPE *setr3;
    fmi3SetInt32TYPE *seti3;
    fmi3SetBooleanTYPE *setb3;
    fmi3GetFloat64TYPE *getr3;
    fmi3GetInt32TYPE *geti3;
    fmi3GetBooleanTYPE *getb3;
    fmi3DoStepTYPE *step3;
    fmi3GetFMUStateTYPE *gets3;
    fmi3SetFMUStateTYPE *sets3;
    fmi3FreeFMUStateTYPE *frees3;
    fmi3SerializedFMUStateSizeTYPE *size3;
    fmi3SerializeFMUStateTYPE *ser3;
    fmi3DeserializeFMUStateTYPE *deser3;
} Api;

/* Messages of Error (or worse) and Discard status logged since the counter was reset. */
static int logged_errors;
static char last_message[512];

/* Appends printf-style text to the string in buf (truncated to size). */
static void append(char *buf, size_t size, const char *fmt, ...)
{
    size_t used = strlen(buf);
    va_list args;
    if (used + 1 >= size) return;
    va_start(args, fmt);
    vsnprintf(buf + used, size - used, fmt, args);
    va_end(args);
}

static void note(int status, const char *message)
{
    if (status >= 2) {
        logged_errors++;
        last_message[0] = '\0';
        append(last_message, sizeof last_message, "%s", message);
    }
}

static void logger2(fmi2ComponentEnvironment env, fmi2String name, fmi2Status status, fmi2String category,
                    fmi2String message, ...)
{
    char text[1024];
    va_list args;
    (void)env;
    (void)name;
    (void)category;
    va_start(args, message);
    vsnprintf(text, sizeof text, message, args);
    va_end(args);
    note((int)status, text);
}

static void logger3(fmi3InstanceEnvironment env, fmi3Status status, fmi3String category, fmi3String message)
{
    (void)env;
    (void)category;
    note((int)status, message);
}

static void *symbol(void *lib, const char *prefix, const char *name)
{
    char full[128];
    void *p;
    snprintf(full, sizeof full, "%s%s", prefix, name);
    p = dlsym(lib, full);
    if (p == NULL) die("the FMU binary has no function %s", full);
    return p;
}

#define LOAD2(field, name) *(void **)(&api->field) = symbol(api->lib, "fmi2", name)
#define LOAD3(field, name) *(void **)(&api->field) = symbol(api->lib, "fmi3", name)

static void load(Api *api, const char *path, int fmi)
{
    memset(api, 0, sizeof *api);
    api->fmi = fmi;
    api->lib = dlopen(path, RTLD_NOW | RTLD_LOCAL);
    if (api->lib == NULL) die("dlopen %s: %s", path, dlerror());
    if (fmi == 2) {
        LOAD2(i2, "Instantiate");
        LOAD2(free2, "FreeInstance");
        LOAD2(setup2, "SetupExperiment");
        LOAD2(enter2, "EnterInitializationMode");
        LOAD2(exit2, "ExitInitializationMode");
        LOAD2(setr2, "SetReal");
        LOAD2(seti2, "SetInteger");
        LOAD2(setb2, "SetBoolean");
        LOAD2(getr2, "GetReal");
        LOAD2(geti2, "GetInteger");
        LOAD2(getb2, "GetBoolean");
        LOAD2(step2, "DoStep");
        LOAD2(gets2, "GetFMUstate");
        LOAD2(sets2, "SetFMUstate");
        LOAD2(frees2, "FreeFMUstate");
        LOAD2(size2, "SerializedFMUstateSize");
        LOAD2(ser2, "SerializeFMUstate");
        LOAD2(deser2, "DeSerializeFMUstate");
    } else {
        LOAD3(i3, "InstantiateCoSimulation");
        LOAD3(free3, "FreeInstance");
        LOAD3(enter3, "EnterInitializationMode");
        LOAD3(exit3, "ExitInitializationMode");
        LOAD3(setr3, "SetFloat64");
        LOAD3(seti3, "SetInt32");
        LOAD3(setb3, "SetBoolean");
        LOAD3(getr3, "GetFloat64");
        LOAD3(geti3, "GetInt32");
        LOAD3(getb3, "GetBoolean");
        LOAD3(step3, "DoStep");
        LOAD3(gets3, "GetFMUState");
        LOAD3(sets3, "SetFMUState");
        LOAD3(frees3, "FreeFMUState");
        LOAD3(size3, "SerializedFMUStateSize");
        LOAD3(ser3, "SerializeFMUState");
        LOAD3(deser3, "DeserializeFMUState");
    }
}

static const fmi2CallbackFunctions callbacks2 = {logger2, calloc, free, NULL, NULL};

static void *instantiate(const Api *api, const Spec *spec, const char *name)
{
    if (api->fmi == 2)
        return api->i2(name, fmi2CoSimulation, spec->token, "file:///tmp", &callbacks2, fmi2False, fmi2False);
    return api->i3(name, spec->token, "/tmp", fmi3False, fmi3False, fmi3False, fmi3False, NULL, 0, NULL, logger3,
                   NULL);
}

static void free_instance(const Api *api, void *c)
{
    if (c == NULL) return;
    if (api->fmi == 2)
        api->free2(c);
    else
        api->free3(c);
}

static int set_value(const Api *api, void *c, const Var *v, double value)
{
    if (v->type == 'R')
        return api->fmi == 2 ? (int)api->setr2(c, &v->vr, 1, &value) : (int)api->setr3(c, &v->vr, 1, &value, 1);
    if (v->type == 'I') {
        int i = (int)value;
        return api->fmi == 2 ? (int)api->seti2(c, &v->vr, 1, &i) : (int)api->seti3(c, &v->vr, 1, &i, 1);
    }
    if (api->fmi == 2) {
        fmi2Boolean b = value != 0.0;
        return (int)api->setb2(c, &v->vr, 1, &b);
    } else {
        fmi3Boolean b = value != 0.0;
        return (int)api->setb3(c, &v->vr, 1, &b, 1);
    }
}

static int get_value(const Api *api, void *c, const Var *v, double *value)
{
    int status;
    if (v->type == 'R') {
        return api->fmi == 2 ? (int)api->getr2(c, &v->vr, 1, value) : (int)api->getr3(c, &v->vr, 1, value, 1);
    } else if (v->type == 'I') {
        int i = 0;
        status = api->fmi == 2 ? (int)api->geti2(c, &v->vr, 1, &i) : (int)api->geti3(c, &v->vr, 1, &i, 1);
        *value = (double)i;
    } else if (api->fmi == 2) {
        fmi2Boolean b = fmi2False;
        status = (int)api->getb2(c, &v->vr, 1, &b);
        *value = b ? 1.0 : 0.0;
    } else {
        fmi3Boolean b = fmi3False;
        status = (int)api->getb3(c, &v->vr, 1, &b, 1);
        *value = b ? 1.0 : 0.0;
    }
    return status;
}

/* Instantiated, parameters set and initialised at t = 0; NULL on failure (message on stderr). */
static void *start(const Api *api, const Spec *spec, const char *name)
{
    void *c = instantiate(api, spec, name);
    int i, status = 0;
    if (c == NULL) {
        fprintf(stderr, "fuzz_state: instantiation failed: %s\n", last_message);
        return NULL;
    }
    if (api->fmi == 2) status = (int)api->setup2(c, fmi2False, 0.0, 0.0, fmi2False, 0.0);
    for (i = 0; i < spec->n_params && status == 0; i++) status = set_value(api, c, &spec->params[i], spec->params[i].value);
    if (status == 0)
        status = api->fmi == 2 ? (int)api->enter2(c) : (int)api->enter3(c, fmi3False, 0.0, 0.0, fmi3False, 0.0);
    if (status == 0) status = api->fmi == 2 ? (int)api->exit2(c) : (int)api->exit3(c);
    if (status != 0) {
        fprintf(stderr, "fuzz_state: initialisation failed (status %d): %s\n", status, last_message);
        free_instance(api, c);
        return NULL;
    }
    return c;
}

/* Sets the inputs of row k and steps from k dt; the FMI status. */
static int step(const Api *api, const Spec *spec, void *c, int k)
{
    const double *row = spec->rows + (size_t)k * (size_t)spec->n_inputs;
    double t = k * spec->dt;
    int i, status;
    for (i = 0; i < spec->n_inputs; i++) {
        status = set_value(api, c, &spec->inputs[i], row[i]);
        if (status != 0) return status;
    }
    if (api->fmi == 2) return (int)api->step2(c, t, spec->dt, fmi2True);
    {
        fmi3Boolean event = fmi3False, terminate = fmi3False, early = fmi3False;
        double last = 0.0;
        return (int)api->step3(c, t, spec->dt, fmi3True, &event, &terminate, &early, &last);
    }
}

static int get_state(const Api *api, void *c, void **state)
{
    return api->fmi == 2 ? (int)api->gets2(c, state) : (int)api->gets3(c, state);
}

static int set_state(const Api *api, void *c, void *state)
{
    return api->fmi == 2 ? (int)api->sets2(c, state) : (int)api->sets3(c, state);
}

static void free_state(const Api *api, void *c, void **state)
{
    if (*state == NULL) return;
    if (api->fmi == 2)
        api->frees2(c, state);
    else
        api->frees3(c, state);
    *state = NULL;
}

static int deserialize(const Api *api, void *c, const unsigned char *bytes, size_t size, void **state)
{
    *state = NULL;
    if (api->fmi == 2) return (int)api->deser2(c, (const fmi2Byte *)bytes, size, state);
    return (int)api->deser3(c, (const fmi3Byte *)bytes, size, state);
}

/* The serialized bytes of the instance's current state (malloc'ed); NULL on failure. */
static unsigned char *serialize(const Api *api, void *c, size_t *size)
{
    void *state = NULL;
    unsigned char *bytes = NULL;
    int status = get_state(api, c, &state);
    if (status == 0) status = api->fmi == 2 ? (int)api->size2(c, state, size) : (int)api->size3(c, state, size);
    if (status == 0 && (bytes = (unsigned char *)malloc(*size)) == NULL) status = 3;
    if (status == 0)
        status = api->fmi == 2 ? (int)api->ser2(c, state, (fmi2Byte *)bytes, *size)
                               : (int)api->ser3(c, state, (fmi3Byte *)bytes, *size);
    free_state(api, c, &state);
    if (status != 0) {
        free(bytes);
        return NULL;
    }
    return bytes;
}

/* ------------------------------------------------------------------ cases */

static const int32_t SWEEP_VALUES[] = {
    0, 1, -1, 2, 7, 255, 65535, 1000000, 0x10000000, INT32_MAX / 2, INT32_MAX, INT32_MIN,
    (int32_t)0x3ff00000,   /* upper word of 1.0 */
    (int32_t)0x7ff00000,   /* upper word of +Inf */
    (int32_t)0xfff00000u,  /* upper word of -Inf */
    (int32_t)0x7ff80000,   /* upper word of a quiet NaN */
};
#define N_SWEEP_VALUES ((long)(sizeof SWEEP_VALUES / sizeof SWEEP_VALUES[0]))

typedef enum { MODE_RANDOM, MODE_RANDOM_SEALED, MODE_SWEEP } FuzzMode;

static uint64_t splitmix(uint64_t *x)
{
    uint64_t z = (*x += 0x9e3779b97f4a7c15ULL);
    z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9ULL;
    z = (z ^ (z >> 27)) * 0x94d049bb133111ebULL;
    return z ^ (z >> 31);
}

static void reseal(unsigned char *bytes, size_t size)
{
    const size_t from = SNAPSHOT_CHECKSUM_OFFSET + 8;
    uint64_t hash = FMU_STATE_CHECKSUM_SEED;
    size_t i;
    for (i = from; i < size; i++) {
        hash ^= bytes[i];
        hash *= 1099511628211ULL; /* 64-bit FNV-1a, as fmu_state_checksum */
    }
    memcpy(bytes + SNAPSHOT_CHECKSUM_OFFSET, &hash, sizeof hash);
}

/* The sweep's case k of `cases`: with every (offset, value) pair (cases = pairs), offset-major;
 * with fewer cases, still every offset (cases >= offsets) with the values rotating. */
static void sweep_case(long k, long cases, size_t size, size_t *offset, int32_t *value)
{
    const long offsets = (long)(size / 4);
    *offset = (size_t)((double)k * (double)offsets / (double)cases) * 4u;
    *value = SWEEP_VALUES[k % N_SWEEP_VALUES];
}

/* Writes case k's corruption into bytes (a copy of the genuine state); a description in text. */
static void corrupt(FuzzMode mode, uint64_t seed, long k, long cases, unsigned char *bytes, size_t size, char *text,
                    size_t text_size)
{
    size_t used = 0;
    if (mode == MODE_SWEEP) {
        size_t offset;
        int32_t value;
        sweep_case(k, cases, size, &offset, &value);
        memcpy(bytes + offset, &value, sizeof value);
        snprintf(text, text_size, "int32 %ld (0x%08x) at offset %lu", (long)value, (unsigned)value,
                 (unsigned long)offset);
    } else {
        uint64_t mix = seed ^ ((uint64_t)k * 0xd1b54a32d192ed03ULL), rng = splitmix(&mix);
        int n = 1 + (int)(splitmix(&rng) % 8u), i;
        size_t chosen[8];
        used = (size_t)snprintf(text, text_size, "%d byte(s):", n);
        for (i = 0; i < n; i++) { /* distinct offsets; resealed: not in the checksum it rewrites */
            size_t offset;
            unsigned char flip;
            int j, again;
            do {
                offset = (size_t)(splitmix(&rng) % size);
                again = mode == MODE_RANDOM_SEALED && offset >= SNAPSHOT_CHECKSUM_OFFSET &&
                        offset < SNAPSHOT_CHECKSUM_OFFSET + 8;
                for (j = 0; j < i; j++) again |= chosen[j] == offset;
            } while (again);
            chosen[i] = offset;
            flip = (unsigned char)(1u + splitmix(&rng) % 255u);
            bytes[offset] ^= flip;
            if (used < text_size)
                used += (size_t)snprintf(text + used, text_size - used, " [%lu]^=0x%02x", (unsigned long)offset, flip);
        }
    }
    if (mode != MODE_RANDOM) reseal(bytes, size);
}

enum {
    OUT_READY = 0,
    OUT_SKIPPED,
    OUT_REJECTED,
    OUT_REJECTED_CHANGED,
    OUT_REJECTED_SILENT,
    OUT_ACCEPTED_SAME,
    OUT_ACCEPTED_DIFFERENT,
    OUT_ACCEPTED_REFUSED,
    OUT_ACCEPTED_INCONSISTENT,
    N_OUTCOMES
};

typedef struct {
    int32_t k, outcome;
} Record;

typedef struct {
    const Api *api;
    const Spec *spec;
    FuzzMode mode;
    uint64_t seed;
    long cases;
    void *c;                 /* the fuzzed instance */
    void *base;              /* the genuine state (deserialized) */
    unsigned char *genuine;  /* its bytes */
    size_t size;
    double *ref;             /* outputs after each of the M steps of an untouched instance */
} Child;

static int same_bits(double a, double b) { return memcmp(&a, &b, sizeof a) == 0; }

/* Reads the outputs (row m of the reference: 0 right after the state was set, m after step m);
 * 0: equal to the reference, 1: different (reason in why), 2: out of range (check_range),
 * 3: a get failed (status in *refused). */
static int check_outputs(Child *ch, int m, int check_range, int *refused, char *why, size_t why_size)
{
    const Spec *spec = ch->spec;
    int i, differs = 0;
    for (i = 0; i < spec->n_outputs; i++) {
        const Var *v = &spec->outputs[i];
        const double expected = ch->ref[m * spec->n_outputs + i];
        double value = NAN;
        int status = get_value(ch->api, ch->c, v, &value);
        if (status != 0) {
            *refused = status;
            snprintf(why, why_size, "getting %s after step %d returned status %d", v->name, m, status);
            append(why, why_size, " (%s)", last_message);
            return 3;
        }
        if (!same_bits(value, expected) && !differs) {
            snprintf(why, why_size, "%s = %.17g after step %d, untouched instance %.17g", v->name, value, m, expected);
            differs = 1;
        }
        if (check_range && !(isnan(value) ? v->nan_ok : (value >= v->lo && value <= v->hi))) {
            snprintf(why, why_size, "output %s = %.17g after step %d is outside [%g, %g]%s", v->name, value, m, v->lo,
                     v->hi, v->nan_ok ? " or NaN" : "");
            return 2;
        }
    }
    return differs;
}

/* Reads the outputs right after the state was set, then steps M times reading them after each
 * step: 0: every output equals the untouched instance's; 1: some differ (reason in why);
 * 2: an output out of range (check_range); 3: a call refused (its status in *refused). */
static int run_steps(Child *ch, int check_range, int *refused, char *why, size_t why_size)
{
    const Spec *spec = ch->spec;
    int m, rc, differs = 0;
    *refused = 0;
    why[0] = '\0';
    for (m = 0; m <= spec->steps; m++) {
        if (m > 0) {
            int status = step(ch->api, spec, ch->c, spec->warmup + m - 1);
            if (status != 0) {
                *refused = status;
                snprintf(why, why_size, "step %d returned status %d", m, status);
                append(why, why_size, " (%s)", last_message);
                return 3;
            }
        }
        rc = check_outputs(ch, m, check_range, refused, why + (differs ? strlen(why) : 0),
                           differs ? why_size - strlen(why) : why_size);
        if (rc >= 2) return rc;
        differs |= rc;
    }
    return differs;
}

static int run_case(Child *ch, long k, unsigned char *bytes, char *text, size_t text_size)
{
    const Api *api = ch->api;
    void *state = NULL;
    char why[768];
    int status, refused, rc;
    memcpy(bytes, ch->genuine, ch->size);
    corrupt(ch->mode, ch->seed, k, ch->cases, bytes, ch->size, text, text_size);
    if (memcmp(bytes, ch->genuine, ch->size) == 0) return OUT_SKIPPED;
    if (set_state(api, ch->c, ch->base) != 0) {
        fprintf(stderr, "fuzz_state: the genuine state cannot be set: %s\n", last_message);
        exit(EXIT_SETUP);
    }
    logged_errors = 0;
    last_message[0] = '\0';
    status = deserialize(api, ch->c, bytes, ch->size, &state);
    if (status == 0) {
        status = set_state(api, ch->c, state);
        free_state(api, ch->c, &state);
    }
    if (status != 0) {
        char message[512];
        int logged = logged_errors > 0;
        memcpy(message, last_message, sizeof message);
        rc = run_steps(ch, 0, &refused, why, sizeof why);
        if (!logged) {
            append(text, text_size, ": rejected (status %d) without an error message",
                     status);
            return OUT_REJECTED_SILENT;
        }
        if (rc != 0) {
            append(text, text_size, ": rejected (%s) but the instance changed: %s",
                     message, why);
            return OUT_REJECTED_CHANGED;
        }
        return OUT_REJECTED;
    }
    logged_errors = 0;
    rc = run_steps(ch, 1, &refused, why, sizeof why);
    if (rc == 0) return OUT_ACCEPTED_SAME;
    if (rc == 1) return OUT_ACCEPTED_DIFFERENT;
    if (rc == 3 && refused >= 2 && logged_errors > 0) return OUT_ACCEPTED_REFUSED;
    append(text, text_size, ": accepted, then %s%s", why, rc == 3 ? " without an error message" : "");
    return OUT_ACCEPTED_INCONSISTENT;
}

static void child_main(const Api *api, const Spec *spec, FuzzMode mode, uint64_t seed, long first, long total,
                       long cases, int fd, unsigned timeout)
{
    Child ch;
    void *ref_instance;
    unsigned char *bytes;
    char text[1024], why[768];
    int i, refused;
    long k;
    Record record;
    memset(&ch, 0, sizeof ch);
    ch.api = api;
    ch.spec = spec;
    ch.mode = mode;
    ch.seed = seed;
    ch.cases = cases;
    alarm(timeout * 10u + 60u);
    /* the untouched instance: warm-up, then the reference outputs of the M steps */
    ch.ref = (double *)calloc((size_t)(spec->steps + 1) * (size_t)(spec->n_outputs + 1), sizeof(double));
    ref_instance = start(api, spec, "untouched");
    ch.c = start(api, spec, "fuzzed");
    if (ch.ref == NULL || ref_instance == NULL || ch.c == NULL) exit(EXIT_SETUP);
    for (k = 0; k < spec->warmup + spec->steps; k++) {
        if (step(api, spec, ref_instance, (int)k) != 0) {
            fprintf(stderr, "fuzz_state: step %ld of the untouched instance failed: %s\n", k, last_message);
            exit(EXIT_SETUP);
        }
        if (k + 1 < spec->warmup) continue;
        for (i = 0; i < spec->n_outputs; i++) {
            double *slot = &ch.ref[(k + 1 - spec->warmup) * spec->n_outputs + i];
            if (get_value(api, ref_instance, &spec->outputs[i], slot) != 0) exit(EXIT_SETUP);
        }
    }
    free_instance(api, ref_instance);
    for (k = 0; k < spec->warmup; k++) {
        if (step(api, spec, ch.c, (int)k) != 0) exit(EXIT_SETUP);
    }
    ch.genuine = serialize(api, ch.c, &ch.size);
    if (ch.genuine == NULL || deserialize(api, ch.c, ch.genuine, ch.size, &ch.base) != 0) {
        fprintf(stderr, "fuzz_state: the state cannot be serialized and deserialized: %s\n", last_message);
        exit(EXIT_SETUP);
    }
    /* the genuine state restored gives the untouched instance's outputs */
    if (set_state(api, ch.c, ch.base) != 0 || run_steps(&ch, 1, &refused, why, sizeof why) != 0) {
        fprintf(stderr, "fuzz_state: the genuine state does not reproduce the untouched instance: %s\n", why);
        exit(EXIT_SETUP);
    }
    bytes = (unsigned char *)malloc(ch.size);
    if (bytes == NULL) exit(EXIT_SETUP);
    alarm(0);
    record.k = -1;
    record.outcome = OUT_READY;
    if (write(fd, &record, sizeof record) != (ssize_t)sizeof record) exit(EXIT_SETUP);
    if (first == 0) printf("state of %lu bytes\n", (unsigned long)ch.size);
    fflush(stdout);
    i = 0; /* failing cases printed by this child */
    for (k = first; k < total; k++) {
        alarm(timeout);
        record.k = (int32_t)k;
        record.outcome = run_case(&ch, k, bytes, text, sizeof text);
        alarm(0);
        if (record.outcome == OUT_REJECTED_CHANGED || record.outcome == OUT_REJECTED_SILENT ||
            record.outcome == OUT_ACCEPTED_INCONSISTENT) {
            if (i++ < MAX_REPORTED) printf("case %ld: %s\n", k, text);
            fflush(stdout);
        }
        if (write(fd, &record, sizeof record) != (ssize_t)sizeof record) exit(EXIT_SETUP);
    }
    free(bytes);
    free_state(api, ch.c, &ch.base);
    free_instance(api, ch.c);
    free(ch.genuine);
    free(ch.ref);
    close(fd);
    exit(0);
}

/* The state's size, from a child that only sets up (so the parent needs no FMU instance). */
static size_t probe_size(const Api *api, const Spec *spec)
{
    void *c = start(api, spec, "probe");
    size_t size = 0;
    unsigned char *bytes;
    int k;
    if (c == NULL) exit(2);
    for (k = 0; k < spec->warmup; k++) {
        if (step(api, spec, c, k) != 0) die("step %d of the warm-up failed: %s", k, last_message);
    }
    bytes = serialize(api, c, &size);
    if (bytes == NULL) die("the state cannot be serialized: %s", last_message);
    free(bytes);
    free_instance(api, c);
    return size;
}

int main(int argc, char **argv)
{
    static const char *const names[N_OUTCOMES] = {"ready", "skipped", "rejected_unchanged", "rejected_changed",
                                                  "rejected_silent", "accepted_same", "accepted_different",
                                                  "accepted_refused", "accepted_inconsistent"};
    static const char *const mode_names[] = {"random", "random-sealed", "sweep"};
    Spec *spec = (Spec *)calloc(1, sizeof(Spec));
    Api api;
    FuzzMode mode = MODE_RANDOM;
    int fmi = 2, a, reported = 0;
    long cases = 1000, total, next = 0, count[N_OUTCOMES], crashes = 0, hangs = 0, sanitizer = 0;
    unsigned long long seed = 1;
    unsigned timeout = 10;
    size_t size;
    if (argc < 3 || spec == NULL) die("usage: fuzz_state <binary> <spec> [--fmi 2|3] [--mode random|random-sealed|sweep] "
                                      "[--cases N] [--seed S] [--timeout SECONDS]");
    for (a = 3; a + 1 < argc; a += 2) {
        if (strcmp(argv[a], "--fmi") == 0) {
            fmi = atoi(argv[a + 1]);
        } else if (strcmp(argv[a], "--mode") == 0) {
            if (strcmp(argv[a + 1], "random") == 0) mode = MODE_RANDOM;
            else if (strcmp(argv[a + 1], "random-sealed") == 0) mode = MODE_RANDOM_SEALED;
            else if (strcmp(argv[a + 1], "sweep") == 0) mode = MODE_SWEEP;
            else die("--mode %s: choose random, random-sealed or sweep", argv[a + 1]);
        } else if (strcmp(argv[a], "--cases") == 0) {
            cases = atol(argv[a + 1]);
        } else if (strcmp(argv[a], "--seed") == 0) {
            seed = strtoull(argv[a + 1], NULL, 10);
        } else if (strcmp(argv[a], "--timeout") == 0) {
            timeout = (unsigned)atoi(argv[a + 1]);
        } else {
            die("unknown option %s", argv[a]);
        }
    }
    if (a != argc) die("option %s needs a value", argv[a]);
    if (fmi != 2 && fmi != 3) die("--fmi %d: choose 2 or 3", fmi);
    if (mode != MODE_SWEEP && cases <= 0) die("--cases %ld: the random modes need a positive number of cases", cases);
    if (timeout < 1) timeout = 1;
    read_spec(argv[2], spec);
    load(&api, argv[1], fmi);
    size = probe_size(&api, spec);
    if (size < 64) die("a state of only %lu bytes", (unsigned long)size);
    if (mode == MODE_SWEEP && (cases <= 0 || cases > (long)(size / 4) * N_SWEEP_VALUES))
        cases = (long)(size / 4) * N_SWEEP_VALUES; /* every pair */
    total = cases;
    memset(count, 0, sizeof count);
    fflush(stdout);
    while (next < total) {
        int fds[2], status;
        pid_t pid;
        Record record;
        int ready = 0;
        if (pipe(fds) != 0) die("pipe: %s", strerror(errno));
        pid = fork();
        if (pid < 0) die("fork: %s", strerror(errno));
        if (pid == 0) {
            close(fds[0]);
            child_main(&api, spec, mode, seed, next, total, cases, fds[1], timeout);
        }
        close(fds[1]);
        while (read(fds[0], &record, sizeof record) == (ssize_t)sizeof record) {
            if (record.outcome == OUT_READY) {
                ready = 1;
                continue;
            }
            count[record.outcome]++;
            next = record.k + 1;
        }
        close(fds[0]);
        if (waitpid(pid, &status, 0) != pid) die("waitpid: %s", strerror(errno));
        if (WIFEXITED(status) && WEXITSTATUS(status) == 0 && next >= total) break;
        if (!ready) die("the child failed before the first case (status 0x%x)", status);
        {
            unsigned char *dummy = (unsigned char *)calloc(size, 1);
            char text[1024];
            if (dummy == NULL) die("out of memory");
            corrupt(mode, seed, next, cases, dummy, size, text, sizeof text);
            free(dummy);
            if (WIFSIGNALED(status) && WTERMSIG(status) == SIGALRM) {
                hangs++;
                if (reported++ < MAX_REPORTED) printf("case %ld: %s: hang (more than %u s)\n", next, text, timeout);
            } else if (WIFEXITED(status) && WEXITSTATUS(status) == EXIT_SANITIZER) {
                sanitizer++;
                crashes++;
                if (reported++ < MAX_REPORTED) printf("case %ld: %s: sanitizer report\n", next, text);
            } else if (WIFSIGNALED(status)) {
                crashes++;
                if (reported++ < MAX_REPORTED) printf("case %ld: %s: crash (signal %d)\n", next, text, WTERMSIG(status));
            } else {
                die("the child ended with status 0x%x at case %ld", status, next);
            }
            fflush(stdout);
        }
        next++;
    }
    printf("RESULT fmi=%d mode=%s state_bytes=%lu cases=%ld rejected=%ld accepted_consistent=%ld "
           "accepted_inconsistent=%ld crashes=%ld hangs=%ld sanitizer=%ld",
           fmi, mode_names[mode], (unsigned long)size, total - count[OUT_SKIPPED],
           count[OUT_REJECTED] + count[OUT_REJECTED_CHANGED] + count[OUT_REJECTED_SILENT],
           count[OUT_ACCEPTED_SAME] + count[OUT_ACCEPTED_DIFFERENT] + count[OUT_ACCEPTED_REFUSED],
           count[OUT_ACCEPTED_INCONSISTENT], crashes, hangs, sanitizer);
    for (a = OUT_SKIPPED; a < OUT_ACCEPTED_INCONSISTENT; a++) printf(" %s=%ld", names[a], count[a]);
    printf("\n");
    free(spec->rows);
    free(spec);
    dlclose(api.lib);
    return 0;
}
