/*
 * duffid_container.c - duffid's container FMU: a discrete-time co-simulation model on the
 * shared FMI glue (fmus/common) whose step runs the Jacobi master of duffid's orchestrator
 * over the FMUs it holds.
 *
 * The components are unpacked in the container's resources/<component>/ folders; at
 * instantiation each binary is loaded (dlopen / LoadLibrary), its FMI 2 or FMI 3 functions
 * resolved and one co-simulation instance made. The container's description (components,
 * connections, the container variables' mapping and its internal step) is the generated
 * header container_fmu_config.h (tables of duffid_container.h): compiled in, nothing to parse.
 *
 * The algorithm is that of System.run(ordering="jacobi") at the internal step CONTAINER_STEP,
 * executed by the orchestrator's own compiled loop (fmus/cosim/duffid_cosim_loop.c):
 *   initialisation: components set up, parameters set, enter initialisation; connected inputs
 *     set from zeros, container inputs set; exit initialisation; connection values read and
 *     set into their targets;
 *   each internal step t_k = start + k h: every component's doStep(t_k, h) with the inputs
 *     held, then every connection source read, then every connection target set (Jacobi).
 * A container doStep of H = n h runs n internal steps; container inputs are passed to their
 * components before, container outputs read from them after (so an output with direct
 * feedthrough shows its connected input's newest value).
 *
 * Every failure of a component (a binary that does not load, a missing function, an
 * instantiation that fails, an FMI call returning Error, or Discard without a request to end
 * the simulation) is logged through the container's logger naming the component and its FMU;
 * a failed internal step discards the container's step (its time and variables stay those of
 * the step's start; the components cannot be rolled back, so only terminate, reset or free
 * may follow). The container refuses FMU state calls (canGetAndSetFMUstate=false).
 *
 * A component asking to end the simulation (FMI 2: Discard with fmi2Terminated true; FMI 3:
 * terminateSimulation, with earlyReturn when it stopped inside its step) ends the container's
 * step in that internal step: the other components complete it, the connected outputs are read
 * (the connected inputs are not set), and the container asks to end the simulation at the
 * earliest time reached by a component that asked (fmu_request_termination: its FMI 2 doStep
 * returns Discard, fmi2GetBooleanStatus(fmi2Terminated) is true, fmi2LastSuccessfulTime is
 * that time, its outputs are read from the components then).
 */
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#ifdef _WIN32
#include <windows.h>
#else
#include <dlfcn.h>
#endif

#include "fmi2FunctionTypes.h"
#include "fmi3FunctionTypes.h"

#include "duffid_container.h"
#include "duffid_cosim_loop.h"
#include "fmu_instance.h"

#include "container_fmu_config.h"

/* Platform folders of the components' binaries (as duffid.cbuild names them). */
#if defined(_WIN32)
#define FOLDER_FMI2 "win64"
#define FOLDER_FMI3 "x86_64-windows"
#define LIBRARY_SUFFIX ".dll"
#elif defined(__APPLE__)
#define FOLDER_FMI2 "darwin64"
#if defined(__aarch64__)
#define FOLDER_FMI3 "aarch64-darwin"
#else
#define FOLDER_FMI3 "x86_64-darwin"
#endif
#define LIBRARY_SUFFIX ".dylib"
#elif defined(__aarch64__)
#define FOLDER_FMI2 "aarch64-linux"
#define FOLDER_FMI3 "aarch64-linux"
#define LIBRARY_SUFFIX ".so"
#else
#define FOLDER_FMI2 "linux64"
#define FOLDER_FMI3 "x86_64-linux"
#define LIBRARY_SUFFIX ".so"
#endif

#define N_COMPONENTS CONTAINER_N_COMPONENTS
#define TIME_VR 0u

/* The FMI functions a component must provide, by FMI version. */
enum { F_INSTANTIATE, F_FREE, F_SETUP, F_ENTER, F_EXIT, F_TERMINATE, F_DO_STEP, F_GET_REAL, F_GET_INT,
       F_GET_BOOL, F_SET_REAL, F_SET_INT, F_SET_BOOL, F_BOOLEAN_STATUS, F_REAL_STATUS, F_ENTER_CONFIGURATION,
       F_EXIT_CONFIGURATION, F_ENTER_EVENT, F_UPDATE_DISCRETE, F_ENTER_STEP, N_FUNCTIONS };
static const char *const FUNCTION_NAMES[2][N_FUNCTIONS] = {
    {"fmi2Instantiate", "fmi2FreeInstance", "fmi2SetupExperiment", "fmi2EnterInitializationMode",
     "fmi2ExitInitializationMode", "fmi2Terminate", "fmi2DoStep", "fmi2GetReal", "fmi2GetInteger",
     "fmi2GetBoolean", "fmi2SetReal", "fmi2SetInteger", "fmi2SetBoolean", "fmi2GetBooleanStatus",
     "fmi2GetRealStatus", NULL, NULL, NULL, NULL, NULL},
    {"fmi3InstantiateCoSimulation", "fmi3FreeInstance", NULL, "fmi3EnterInitializationMode",
     "fmi3ExitInitializationMode", "fmi3Terminate", "fmi3DoStep", "fmi3GetFloat64", "fmi3GetInt32",
     "fmi3GetBoolean", "fmi3SetFloat64", "fmi3SetInt32", "fmi3SetBoolean", NULL, NULL,
     "fmi3EnterConfigurationMode", "fmi3ExitConfigurationMode", "fmi3EnterEventMode", "fmi3UpdateDiscreteStates",
     "fmi3EnterStepMode"}};

/* Where a component is in its lifecycle. */
enum { STAGE_NONE, STAGE_LOADED, STAGE_INSTANTIATED, STAGE_INITIALIZING, STAGE_STEPPING, STAGE_TERMINATED };

typedef struct Component {
    const ContainerComponent *info;
    Instance *owner;                   /* the container instance (its logger) */
    int stage;
    void *library;
    void *instance;
    duffid_function f[N_FUNCTIONS];
    duffid_function io[CONTAINER_N_KINDS][2]; /* get and set of each connection kind (NULL: none) */
    fmi2CallbackFunctions callbacks;   /* FMI 2: must outlive the instance */
    /* doStep outputs of FMI 3 */
    _Bool event_handling_needed, terminate, early_return;
    double last_successful_time;
} Component;

typedef struct Container {
    Component comps[N_COMPONENTS];
    /* the loop's operations: per internal step stage 0 (doSteps, gets, posts) then stage 1 (sets) */
    duffid_stage stages[2], init_stages[2];
    duffid_io_op *sets, *gets;
    duffid_step_op steps[N_COMPONENTS];
    duffid_move *posts;
    int n_sets, n_gets, n_posts;
    int *set_component, *get_component;  /* component of each set / get op */
    int *set_kind, *get_kind;            /* connection kind of each set / get op */
    /* connection values, one buffer per kind; staging of gets whose FMI values differ in size from
     * their buffer's (FMI 3 Boolean, FMI 2 Enumeration); the set ops' own value arrays */
    unsigned char *values[CONTAINER_N_KINDS];
    size_t count[CONTAINER_N_KINDS];     /* values in each buffer */
    unsigned char *staging, *set_values;
    unsigned *source_vr, *target_vr;
    struct ObjectOp *object_ops;         /* the String and Binary gets and sets (the container copies them) */
    int n_object_ops;
    /* the container inputs and parameters as last passed to the components */
    double *sent;
    unsigned char *sent_valid;
    double *grid;
    long grid_size;
} Container;

static const char *status_name(int status)
{
    static const char *const names[] = {"OK", "Warning", "Discard", "Error", "Fatal", "Pending"};
    return status >= 0 && status <= 5 ? names[status] : "an unknown status";
}

static const char *component_kind(const Component *k) { return k->info->fmi_version == 2 ? "FMI 2" : "FMI 3"; }

/* ------------------------------------------------------------------ logging */

static void log_component(Component *k, int status, const char *category, const char *text)
{
    FmuStatus s = status < 0 || status > FMU_FATAL ? FMU_ERROR : (FmuStatus)status;
    fmu_log(k->owner, s, category ? category : "logAll", "component '%s' (%s): %s", k->info->name, k->info->fmu,
            text ? text : "");
}

static void logger2(fmi2ComponentEnvironment env, fmi2String name, fmi2Status status, fmi2String category,
                    fmi2String message, ...)
{
    char text[1024];
    va_list args;
    (void)name;
    if (env == NULL) return;
    if (message == NULL) {
        text[0] = '\0';
    } else {
        va_start(args, message);
        vsnprintf(text, sizeof text, message, args);
        va_end(args);
    }
    log_component((Component *)env, (int)status, category, text);
}

static void logger3(fmi3InstanceEnvironment env, fmi3Status status, fmi3String category, fmi3String message)
{
    if (env != NULL) log_component((Component *)env, (int)status, category, message);
}

static void fail(Component *k, const char *fmt, ...)
#if defined(__GNUC__)
    __attribute__((format(printf, 2, 3)))
#endif
    ;

/* An error of component k, logged through the container (naming the component and its FMU). */
static void fail(Component *k, const char *fmt, ...)
{
    char text[800];
    va_list args;
    va_start(args, fmt);
    vsnprintf(text, sizeof text, fmt, args);
    va_end(args);
    fmu_log(k->owner, FMU_ERROR, "logStatusError", "component '%s' (%s, %s): %s", k->info->name, k->info->fmu,
            component_kind(k), text);
}

/* Nonzero (logged) when an FMI call of component k did not succeed. */
static int call_failed(Component *k, const char *function, int status, double t)
{
    if (status <= 1) return 0;
    fail(k, "%s returned %s at t = %.17g", function, status_name(status), t);
    return 1;
}

/* ------------------------------------------------------------------ paths */

static int hex_value(char c)
{
    if (c >= '0' && c <= '9') return c - '0';
    if (c >= 'a' && c <= 'f') return c - 'a' + 10;
    if (c >= 'A' && c <= 'F') return c - 'A' + 10;
    return -1;
}

/* The folder of the container's resources (malloc'd, no trailing separator) from the FMI 2
 * fmuResourceLocation URI or the FMI 3 resourcePath; NULL (logged) when it is not usable. */
static char *resource_folder(Instance *inst)
{
    const char *loc = inst->resource_location, *p;
    char *out;
    size_t i = 0, n;
    if (loc == NULL) {
        fmu_log(inst, FMU_ERROR, "logStatusError", "the resource location is NULL: the container loads its "
                "components from its resources folder");
        return NULL;
    }
    p = loc;
    if (strncmp(p, "file:", 5) == 0) {
        p += 5;
        if (strncmp(p, "//", 2) == 0) { /* an authority: empty or localhost */
            p += 2;
            if (strncmp(p, "localhost", 9) == 0) p += 9;
            if (*p != '/') {
                fmu_log(inst, FMU_ERROR, "logStatusError", "resource location %s: only local file: URIs are "
                        "supported", loc);
                return NULL;
            }
        }
#ifdef _WIN32
        if (p[0] == '/' && p[1] != '\0' && p[2] == ':') p++; /* file:///C:/... */
#endif
    } else if (inst->fmi_version == 2) {
        fmu_log(inst, FMU_ERROR, "logStatusError", "fmuResourceLocation %s is not a file: URI", loc);
        return NULL;
    }
    n = strlen(p);
    out = (char *)malloc(n + 1);
    if (out == NULL) return NULL;
    for (; *p != '\0'; p++) {
        if (*p == '%' && p != loc && strncmp(loc, "file:", 5) == 0) {
            int hi = hex_value(p[1]), lo = hi < 0 ? -1 : hex_value(p[2]);
            if (hi < 0 || lo < 0 || (hi == 0 && lo == 0)) {
                fmu_log(inst, FMU_ERROR, "logStatusError", "resource location %s: invalid percent-encoding", loc);
                free(out);
                return NULL;
            }
            out[i++] = (char)(hi * 16 + lo);
            p += 2;
        } else {
            out[i++] = *p;
        }
    }
    while (i > 1 && (out[i - 1] == '/' || out[i - 1] == '\\')) i--;
    out[i] = '\0';
    if (i == 0) {
        fmu_log(inst, FMU_ERROR, "logStatusError", "the resource location %s names no folder", loc);
        free(out);
        return NULL;
    }
    return out;
}

/* A file: URI of folder `path` (malloc'd), percent-encoding everything but unreserved characters. */
static char *file_uri(const char *path)
{
    static const char hex[] = "0123456789ABCDEF";
    size_t n = strlen(path), i, j = 0;
    char *uri = (char *)malloc(3 * n + 16);
    if (uri == NULL) return NULL;
    strcpy(uri, "file://");
    j = strlen(uri);
    if (path[0] != '/') uri[j++] = '/'; /* C:/... */
    for (i = 0; i < n; i++) {
        unsigned char c = (unsigned char)path[i];
        if (c == '\\') c = '/';
        if ((c >= 'a' && c <= 'z') || (c >= 'A' && c <= 'Z') || (c >= '0' && c <= '9') || strchr("-._~/:", c)) {
            uri[j++] = (char)c;
        } else {
            uri[j++] = '%';
            uri[j++] = hex[c >> 4];
            uri[j++] = hex[c & 15];
        }
    }
    uri[j] = '\0';
    return uri;
}

static char *joined(const char *a, const char *b, const char *c, const char *d, const char *e)
{
    size_t n = strlen(a) + strlen(b) + strlen(c) + strlen(d) + strlen(e) + 1;
    char *s = (char *)malloc(n);
    if (s != NULL) snprintf(s, n, "%s%s%s%s%s", a, b, c, d, e);
    return s;
}

/* ------------------------------------------------------------------ loading */

static void *open_library(const char *path, char *why, size_t why_size)
{
#ifdef _WIN32
    HMODULE h = LoadLibraryA(path);
    if (h == NULL) snprintf(why, why_size, "Windows error %lu", (unsigned long)GetLastError());
    return (void *)h;
#else
    void *h = dlopen(path, RTLD_NOW | RTLD_LOCAL);
    if (h == NULL) {
        const char *e = dlerror();
        snprintf(why, why_size, "%s", e ? e : "unknown error");
    }
    return h;
#endif
}

static duffid_function find_function(void *library, const char *name)
{
#ifdef _WIN32
    return (duffid_function)GetProcAddress((HMODULE)library, name);
#else
    duffid_function f;
    void *p = dlsym(library, name);
    memcpy(&f, &p, sizeof f);
    return f;
#endif
}

static void close_library(void *library)
{
#ifdef _WIN32
    FreeLibrary((HMODULE)library);
#else
    dlclose(library);
#endif
}

/* Loads component k's binary and makes its instance; nonzero (logged) on failure. */
static int load_component(Instance *inst, Component *k, const char *folder)
{
    const ContainerComponent *info = k->info;
    const int v = info->fmi_version == 2 ? 0 : 1;
    char why[512], *binary, *resources, *uri = NULL;
    int i;
    binary = joined(folder, "/", info->name, "/binaries/", v == 0 ? FOLDER_FMI2 : FOLDER_FMI3);
    if (binary != NULL) {
        char *full = joined(binary, "/", info->model_identifier, LIBRARY_SUFFIX, "");
        free(binary);
        binary = full;
    }
    resources = joined(folder, "/", info->name, "/resources", v == 0 ? "" : "/");
    if (binary == NULL || resources == NULL) {
        free(binary);
        free(resources);
        fail(k, "out of memory");
        return 1;
    }
#ifdef _WIN32
    for (i = 0; binary[i] != '\0'; i++)
        if (binary[i] == '/') binary[i] = '\\';
    for (i = 0; resources[i] != '\0'; i++)
        if (resources[i] == '/') resources[i] = '\\';
#endif
    k->library = open_library(binary, why, sizeof why);
    if (k->library == NULL) {
        fail(k, "its binary %s cannot be loaded: %s", binary, why);
        free(binary);
        free(resources);
        return 1;
    }
    k->stage = STAGE_LOADED;
    for (i = 0; i < 2 * CONTAINER_N_KINDS; i++) {
        const char *name = (i % 2 ? container_set_names : container_get_names)[v][i / 2];
        if (name == NULL) continue;
        k->io[i / 2][i % 2] = find_function(k->library, name);
        if (k->io[i / 2][i % 2] == NULL) {
            fail(k, "its binary %s does not export %s", binary, name);
            free(binary);
            free(resources);
            return 1;
        }
    }
    for (i = 0; i < N_FUNCTIONS; i++) {
        const char *name = FUNCTION_NAMES[v][i];
        if (name == NULL) continue;
        k->f[i] = find_function(k->library, name);
        if (k->f[i] == NULL) {
            fail(k, "its binary %s does not export %s", binary, name);
            free(binary);
            free(resources);
            return 1;
        }
    }
    free(binary);
    if (v == 0) {
        uri = file_uri(resources);
        if (uri == NULL) {
            free(resources);
            fail(k, "out of memory");
            return 1;
        }
        k->callbacks.logger = logger2;
        k->callbacks.allocateMemory = calloc;
        k->callbacks.freeMemory = free;
        k->callbacks.stepFinished = NULL;
        k->callbacks.componentEnvironment = k;
        k->instance = ((fmi2InstantiateTYPE *)k->f[F_INSTANTIATE])(info->name, fmi2CoSimulation, info->token, uri,
                                                                    &k->callbacks, fmi2False,
                                                                    inst->logging_on ? fmi2True : fmi2False);
    } else {
        k->instance = ((fmi3InstantiateCoSimulationTYPE *)k->f[F_INSTANTIATE])(
            info->name, info->token, resources, fmi3False, inst->logging_on ? fmi3True : fmi3False,
            info->event_mode ? fmi3True : fmi3False, fmi3False, NULL, 0, k, logger3, NULL);
    }
    free(uri);
    free(resources);
    if (k->instance == NULL) {
        fail(k, "%s failed (returned NULL)", FUNCTION_NAMES[v][F_INSTANTIATE]);
        return 1;
    }
    k->stage = STAGE_INSTANTIATED;
    return 0;
}

/* ------------------------------------------------------------------ single values */

/* Sets one value of `type` (VARTYPE_*) into component k; the FMI status. */
static int set_value(Component *k, int type, unsigned vr, double value)
{
    if (k->info->fmi_version == 2) {
        if (type == VARTYPE_FLOAT64) return ((fmi2SetRealTYPE *)k->f[F_SET_REAL])(k->instance, &vr, 1, &value);
        {
            fmi2Integer x = type == VARTYPE_BOOLEAN ? (value != 0.0) : (fmi2Integer)value;
            return ((fmi2SetIntegerTYPE *)k->f[type == VARTYPE_BOOLEAN ? F_SET_BOOL : F_SET_INT])(k->instance, &vr,
                                                                                                 1, &x);
        }
    }
    if (type == VARTYPE_FLOAT64) return ((fmi3SetFloat64TYPE *)k->f[F_SET_REAL])(k->instance, &vr, 1, &value, 1);
    if (type == VARTYPE_BOOLEAN) {
        fmi3Boolean b = value != 0.0;
        return ((fmi3SetBooleanTYPE *)k->f[F_SET_BOOL])(k->instance, &vr, 1, &b, 1);
    }
    {
        fmi3Int32 x = (fmi3Int32)value;
        return ((fmi3SetInt32TYPE *)k->f[F_SET_INT])(k->instance, &vr, 1, &x, 1);
    }
}

/* Reads one value of `type` from component k into *value; the FMI status. */
static int get_value(Component *k, int type, unsigned vr, double *value)
{
    int status;
    if (k->info->fmi_version == 2) {
        fmi2Integer x = 0;
        if (type == VARTYPE_FLOAT64) return ((fmi2GetRealTYPE *)k->f[F_GET_REAL])(k->instance, &vr, 1, value);
        status = ((fmi2GetIntegerTYPE *)k->f[type == VARTYPE_BOOLEAN ? F_GET_BOOL : F_GET_INT])(k->instance, &vr, 1,
                                                                                               &x);
        *value = type == VARTYPE_BOOLEAN ? (x != 0) : (double)x;
        return status;
    }
    if (type == VARTYPE_FLOAT64) return ((fmi3GetFloat64TYPE *)k->f[F_GET_REAL])(k->instance, &vr, 1, value, 1);
    if (type == VARTYPE_BOOLEAN) {
        fmi3Boolean b = 0;
        status = ((fmi3GetBooleanTYPE *)k->f[F_GET_BOOL])(k->instance, &vr, 1, &b, 1);
        *value = b ? 1.0 : 0.0;
        return status;
    }
    {
        fmi3Int32 x = 0;
        status = ((fmi3GetInt32TYPE *)k->f[F_GET_INT])(k->instance, &vr, 1, &x, 1);
        *value = (double)x;
        return status;
    }
}

static const char *set_name(const Component *k, int type)
{
    return FUNCTION_NAMES[k->info->fmi_version == 2 ? 0 : 1][type == VARTYPE_FLOAT64 ? F_SET_REAL :
                                                             type == VARTYPE_BOOLEAN ? F_SET_BOOL : F_SET_INT];
}

static const char *get_name(const Component *k, int type)
{
    return FUNCTION_NAMES[k->info->fmi_version == 2 ? 0 : 1][type == VARTYPE_FLOAT64 ? F_GET_REAL :
                                                             type == VARTYPE_BOOLEAN ? F_GET_BOOL : F_GET_INT];
}

static int var_type(unsigned vr) { return container_types[vr]; }

/* Passes the container's inputs or parameters (`causality`) whose value changed since they were
 * last passed (or all, `all`) to the component variables they map to; nonzero (logged) on failure. */
static int pass_values(Instance *inst, int causality, int all)
{
    Container *c = (Container *)inst->model_data;
    size_t i;
    for (i = 0; i < CONTAINER_N_LINKS; i++) {
        const ContainerLink *l = &container_links[i];
        unsigned cvr = l->container_vr;
        Component *k = &c->comps[l->component];
        int status;
        if (container_causality[cvr] != causality) continue;
        if (!all && c->sent_valid[cvr] && c->sent[cvr] == inst->vars[cvr]) continue;
        status = set_value(k, var_type(cvr), l->vr, inst->vars[cvr]);
        if (status > 1) {
            fail(k, "%s of %s (from the container's %s) returned %s at t = %.17g", set_name(k, var_type(cvr)),
                 container_link_names[i], container_names[cvr], status_name(status), inst->time);
            return 1;
        }
    }
    for (i = 0; i < CONTAINER_N_LINKS; i++) {
        unsigned cvr = container_links[i].container_vr;
        if (container_causality[cvr] != causality) continue;
        c->sent[cvr] = inst->vars[cvr];
        c->sent_valid[cvr] = 1;
    }
    return 0;
}

/* Reads the container's outputs from their components; nonzero (logged) on failure. */
static int read_outputs(Instance *inst)
{
    Container *c = (Container *)inst->model_data;
    size_t i;
    for (i = 0; i < CONTAINER_N_LINKS; i++) {
        const ContainerLink *l = &container_links[i];
        unsigned cvr = l->container_vr;
        Component *k = &c->comps[l->component];
        int status;
        if (container_causality[cvr] != CAUSALITY_OUTPUT) continue;
        status = get_value(k, var_type(cvr), l->vr, &inst->vars[cvr]);
        if (status > 1) {
            fail(k, "%s of %s (the container's output %s) returned %s at t = %.17g", get_name(k, var_type(cvr)),
                 container_link_names[i], container_names[cvr], status_name(status), inst->time);
            return 1;
        }
    }
    return 0;
}

/* ------------------------------------------------------------------ the loop's operations */

/* A get or set of String or Binary values, which the container copies into memory it owns (an FMU's
 * own is valid only until its next call): an operation of the loop's own (duffid_io_op.call). */
typedef struct ObjectOp {
    Component *k;
    int kind, fmi3, setting;
    const unsigned *vr;
    size_t nvr, n_values;
    unsigned char *buffer;  /* the kind's buffer: char * (String) or ContainerBinary (Binary) values */
    size_t slot;            /* get: the first slot written */
    const intptr_t *slots;  /* set: the slot of each value */
    void **pointers;        /* scratch: a pointer per value */
    size_t *sizes;          /* scratch: a size per value (Binary) */
} ObjectOp;

/* Replaces *owned by a copy of `size` bytes of `data` (plus a terminating zero); nonzero without memory. */
static int own_copy(unsigned char **owned, const void *data, size_t size)
{
    unsigned char *copy = (unsigned char *)malloc(size + 1);
    if (copy == NULL) return 1;
    if (size > 0) memcpy(copy, data, size);
    copy[size] = 0;
    free(*owned);
    *owned = copy;
    return 0;
}

static int string_op(ObjectOp *o)
{
    char **values = (char **)o->buffer;
    const duffid_function f = o->k->io[o->kind][o->setting];
    size_t i;
    int status;
    if (o->setting) {
        for (i = 0; i < o->n_values; i++) {
            const char *v = values[o->slots[i]];
            o->pointers[i] = (void *)(v != NULL ? v : "");
        }
        return o->fmi3 ? ((fmi3SetStringTYPE *)f)(o->k->instance, o->vr, o->nvr, (const fmi3String *)o->pointers,
                                                  o->n_values)
                       : ((fmi2SetStringTYPE *)f)(o->k->instance, o->vr, o->nvr, (const fmi2String *)o->pointers);
    }
    status = o->fmi3 ? ((fmi3GetStringTYPE *)f)(o->k->instance, o->vr, o->nvr, (fmi3String *)o->pointers, o->n_values)
                     : ((fmi2GetStringTYPE *)f)(o->k->instance, o->vr, o->nvr, (fmi2String *)o->pointers);
    for (i = 0; status <= 1 && i < o->n_values; i++) {
        const char *v = o->pointers[i] != NULL ? (const char *)o->pointers[i] : "";
        if (own_copy((unsigned char **)&values[o->slot + i], v, strlen(v))) return fmi3Error;
    }
    return status;
}

static int binary_op(ObjectOp *o)
{
    ContainerBinary *values = (ContainerBinary *)o->buffer;
    const duffid_function f = o->k->io[o->kind][o->setting];
    size_t i;
    int status;
    if (o->setting) {
        for (i = 0; i < o->n_values; i++) {
            const ContainerBinary *b = &values[o->slots[i]];
            o->pointers[i] = (void *)(b->data != NULL ? b->data : (unsigned char *)"");
            o->sizes[i] = b->size;
        }
        return ((fmi3SetBinaryTYPE *)f)(o->k->instance, o->vr, o->nvr, o->sizes, (const fmi3Binary *)o->pointers,
                                       o->n_values);
    }
    status = ((fmi3GetBinaryTYPE *)f)(o->k->instance, o->vr, o->nvr, o->sizes, (fmi3Binary *)o->pointers, o->n_values);
    for (i = 0; status <= 1 && i < o->n_values; i++) {
        ContainerBinary *b = &values[o->slot + i];
        if (own_copy(&b->data, o->pointers[i] != NULL ? o->pointers[i] : "", o->pointers[i] != NULL ? o->sizes[i] : 0))
            return fmi3Error;
        b->size = o->pointers[i] != NULL ? o->sizes[i] : 0;
    }
    return status;
}

static int object_op(void *context)
{
    ObjectOp *o = (ObjectOp *)context;
    return o->kind == CONTAINER_KIND_STRING ? string_op(o) : binary_op(o);
}

/* Makes `op` the String or Binary operation o (scratch for n values); nonzero without memory. */
static int object_io(duffid_io_op *op, ObjectOp *o)
{
    o->pointers = (void **)calloc(o->n_values + 1, sizeof(void *));
    o->sizes = (size_t *)calloc(o->n_values + 1, sizeof(size_t));
    if (o->pointers == NULL || o->sizes == NULL) return 1;
    op->call = object_op;
    op->context = o;
    return 0;
}

static int is_object_kind(int kind) { return kind == CONTAINER_KIND_STRING || kind == CONTAINER_KIND_BINARY; }

/* The loop's conversion of values of `from` bytes into values of `to` bytes. */
static int conversion(size_t from, size_t to)
{
    if (from == to) return DUFFID_COPY;
    if (from == 4 && to == 1) return DUFFID_INT32_TO_BOOL;
    if (from == 1 && to == 4) return DUFFID_BOOL_TO_INT32;
    return from == 8 ? DUFFID_INT64_TO_INT32 : DUFFID_INT32_TO_INT64;
}

/* Builds the set, step, get and post operations of the internal steps; nonzero on lack of memory. */
static int build_ops(Container *c)
{
    const size_t ns = CONTAINER_N_SOURCES, nt = CONTAINER_N_TARGETS;
    size_t i, j, count[CONTAINER_N_KINDS] = {0}, n_source_values = 0, staged = 0, set_at = 0;
    int kind;
    for (i = 0; i < ns; i++) {
        const ContainerSource *s = &container_sources[i];
        if ((size_t)(s->slot + s->n) > count[s->kind]) count[s->kind] = (size_t)(s->slot + s->n);
        n_source_values += (size_t)s->n;
    }
    for (kind = 0; kind < CONTAINER_N_KINDS; kind++) {
        c->values[kind] = (unsigned char *)calloc(count[kind] + 1, container_buffer_size[kind]);
        if (c->values[kind] == NULL) return 1;
        c->count[kind] = count[kind];
    }
    c->object_ops = (ObjectOp *)calloc(ns + nt + 1, sizeof(ObjectOp));
    if (c->object_ops == NULL) return 1;
    c->staging = (unsigned char *)calloc(n_source_values + 1, 8);
    c->set_values = (unsigned char *)calloc(CONTAINER_N_TARGET_VALUES + 1, 8);
    c->source_vr = (unsigned *)calloc(ns + 1, sizeof(unsigned));
    c->target_vr = (unsigned *)calloc(nt + 1, sizeof(unsigned));
    c->gets = (duffid_io_op *)calloc(ns + 1, sizeof(duffid_io_op));
    c->get_component = (int *)calloc(ns + 1, sizeof(int));
    c->get_kind = (int *)calloc(ns + 1, sizeof(int));
    c->posts = (duffid_move *)calloc(ns + 1, sizeof(duffid_move));
    c->sets = (duffid_io_op *)calloc(nt + 1, sizeof(duffid_io_op));
    c->set_component = (int *)calloc(nt + 1, sizeof(int));
    c->set_kind = (int *)calloc(nt + 1, sizeof(int));
    if (!c->staging || !c->set_values || !c->source_vr || !c->target_vr || !c->gets || !c->get_component ||
        !c->get_kind || !c->posts || !c->sets || !c->set_component || !c->set_kind)
        return 1;
    for (i = 0; i < ns; i++) c->source_vr[i] = container_sources[i].vr;
    for (i = 0; i < nt; i++) c->target_vr[i] = container_targets[i].vr;
    /* gets: one per run of sources of one component and kind (their slots are consecutive) */
    for (i = 0; i < ns; i = j) {
        const ContainerSource *s = &container_sources[i];
        Component *k = &c->comps[s->component];
        const int v = k->info->fmi_version == 3;
        const size_t fmi_size = container_fmi_size[v][s->kind], size = container_buffer_size[s->kind];
        unsigned char *destination = c->values[s->kind] + (size_t)s->slot * size;
        duffid_io_op *op = &c->gets[c->n_gets];
        size_t n_values = 0;
        for (j = i; j < ns && container_sources[j].component == s->component && container_sources[j].kind == s->kind;
             j++)
            n_values += (size_t)container_sources[j].n;
        op->function = k->io[s->kind][0];
        op->instance = k->instance;
        op->vr = c->source_vr + i;
        op->n = j - i;
        op->n_values = n_values;
        op->fmi3 = v;
        op->convert = DUFFID_COPY;
        if (is_object_kind(s->kind)) { /* copied by the container */
            ObjectOp *o = &c->object_ops[c->n_object_ops++];
            o->k = k, o->kind = s->kind, o->fmi3 = v, o->setting = 0, o->vr = op->vr, o->nvr = op->n;
            o->n_values = n_values, o->buffer = c->values[s->kind], o->slot = (size_t)s->slot;
            if (object_io(op, o)) return 1;
        } else if (fmi_size == size) {
            op->value = destination;
        } else { /* into staging, then converted into the kind's buffer */
            duffid_move *m = &c->posts[c->n_posts++];
            op->value = c->staging + staged;
            m->destination = (char *)destination;
            m->source = (const char *)(c->staging + staged);
            m->n = n_values;
            m->itemsize = fmi_size;
            m->convert = conversion(fmi_size, size);
            staged += n_values * 8; /* 8-byte aligned for the next run */
        }
        c->get_kind[c->n_gets] = s->kind;
        c->get_component[c->n_gets++] = s->component;
    }
    /* sets: one per run of targets of one component and kind, gathered from the slots */
    for (i = 0; i < nt; i = j) {
        const ContainerTarget *t = &container_targets[i];
        Component *k = &c->comps[t->component];
        const int v = k->info->fmi_version == 3;
        const size_t fmi_size = container_fmi_size[v][t->kind], size = container_buffer_size[t->kind];
        duffid_io_op *op = &c->sets[c->n_sets];
        size_t n_values = 0;
        for (j = i; j < nt && container_targets[j].component == t->component && container_targets[j].kind == t->kind;
             j++)
            n_values += (size_t)container_targets[j].n;
        op->function = k->io[t->kind][1];
        op->instance = k->instance;
        op->vr = c->target_vr + i;
        op->n = j - i;
        op->n_values = n_values;
        op->fmi3 = v;
        op->gather_index = container_target_slots + t->first;
        op->gather_source = (const char *)c->values[t->kind];
        op->itemsize = size;
        op->value = c->set_values + set_at;
        op->convert = conversion(size, fmi_size);
        set_at += n_values * 8;
        if (is_object_kind(t->kind)) { /* copied by the container */
            ObjectOp *o = &c->object_ops[c->n_object_ops++];
            o->k = k, o->kind = t->kind, o->fmi3 = v, o->setting = 1, o->vr = op->vr, o->nvr = op->n;
            o->n_values = n_values, o->buffer = c->values[t->kind], o->slots = op->gather_index;
            op->gather_index = NULL;
            if (object_io(op, o)) return 1;
        }
        c->set_kind[c->n_sets] = t->kind;
        c->set_component[c->n_sets++] = t->component;
    }
    for (i = 0; i < N_COMPONENTS; i++) {
        Component *k = &c->comps[i];
        duffid_step_op *op = &c->steps[i];
        op->function = k->f[F_DO_STEP];
        op->instance = k->instance;
        op->fmi3 = k->info->fmi_version == 3;
        op->event_handling_needed = &k->event_handling_needed;
        op->terminate = &k->terminate;
        op->early_return = &k->early_return;
        op->last_successful_time = &k->last_successful_time;
        op->event_mode = k->info->event_mode;
    }
    /* an internal step: doSteps, gets, posts; then sets.  Initialisation: gets, posts; then sets. */
    memset(c->stages, 0, sizeof c->stages);
    c->stages[0].step_hi = N_COMPONENTS;
    c->stages[0].get_hi = c->n_gets;
    c->stages[0].post_hi = c->n_posts;
    c->stages[1].set_hi = c->n_sets;
    memcpy(c->init_stages, c->stages, sizeof c->stages);
    c->init_stages[0].step_hi = 0;
    return 0;
}

/* The loop's doStep callback: any doStep that does not simply succeed stops the loop at once;
 * run_loop then tells a request to end the simulation from a failure. */
static int stop_on_step(int step_op, int status, long step)
{
    (void)step_op;
    (void)status;
    (void)step;
    return 1;
}

/* Nonzero when component k's doStep from t (returning `status`) asked to end the simulation:
 * FMI 2 Discard with fmi2Terminated true, FMI 3 terminateSimulation; *reached = the time it
 * reached (fmi2LastSuccessfulTime, FMI 3 lastSuccessfulTime: the container does not allow early
 * returns, but an FMU that stops inside its step says where in lastSuccessfulTime, and one that
 * completed it gives t + h), within [t, t + h]. */
static int asked_to_end(Component *k, int status, double t, double *reached)
{
    const double h = CONTAINER_STEP;
    double r = t + h;
    if (k->info->fmi_version == 2) {
        fmi2Boolean terminated = fmi2False;
        fmi2Real last = t;
        if (status != fmi2Discard ||
            ((fmi2GetBooleanStatusTYPE *)k->f[F_BOOLEAN_STATUS])(k->instance, fmi2Terminated, &terminated) > 1 ||
            !terminated)
            return 0;
        if (((fmi2GetRealStatusTYPE *)k->f[F_REAL_STATUS])(k->instance, fmi2LastSuccessfulTime, &last) > 1) last = t;
        r = last;
    } else {
        if (status > 1 || !k->terminate) return 0;
        r = k->last_successful_time;
    }
    *reached = isfinite(r) ? fmin(fmax(r, t), t + h) : t;
    return 1;
}

/* Logs the failure of the loop's operation `op` (DUFFID_LOOP_* code rc) at internal step k_failed. */
static void loop_failed(Container *c, int rc, int op, int status, long k_failed, long n)
{
    double t = c->grid[k_failed];
    if (rc == DUFFID_LOOP_SET_FAILED) {
        Component *k = &c->comps[c->set_component[op]];
        fail(k, "%s of its connected inputs returned %s at t = %.17g",
             container_set_names[k->info->fmi_version - 2][c->set_kind[op]], status_name(status), t);
    } else if (rc == DUFFID_LOOP_GET_FAILED) {
        Component *k = &c->comps[c->get_component[op]];
        fail(k, "%s of its connected outputs returned %s at t = %.17g",
             container_get_names[k->info->fmi_version - 2][c->get_kind[op]], status_name(status),
             n == 0 ? t : c->grid[k_failed + 1]);
    } else {
        Component *k = &c->comps[op];
        if (status >= FMU_ERROR) k->stage = STAGE_TERMINATED; /* after Error: free or reset only */
        fail(k, "%s returned %s in the step from t = %.17g (internal step %.17g s)",
             FUNCTION_NAMES[k->info->fmi_version - 2][F_DO_STEP], status_name(status), t, CONTAINER_STEP);
    }
}

/* The events of component k (with Event Mode) at time t: Event Mode entered (unless `entered`), the
 * discrete states updated until settled, back to Step Mode; nonzero (logged) on failure. A request to
 * end the simulation in the update is refused as a failure (the container ends only at a doStep). */
static int handle_events(Component *k, double t, int entered)
{
    fmi3Boolean again = fmi3True, terminate = fmi3False, nominals, values, defined;
    fmi3Float64 next;
    int status, i;
    if (!entered) {
        status = ((fmi3EnterEventModeTYPE *)k->f[F_ENTER_EVENT])(k->instance);
        if (call_failed(k, "fmi3EnterEventMode", status, t)) return 1;
    }
    for (i = 0; again && i < 100; i++) {
        status = ((fmi3UpdateDiscreteStatesTYPE *)k->f[F_UPDATE_DISCRETE])(k->instance, &again, &terminate, &nominals,
                                                                           &values, &defined, &next);
        if (call_failed(k, "fmi3UpdateDiscreteStates", status, t)) return 1;
        if (terminate) {
            fail(k, "asked to end the simulation in Event Mode at t = %.17g, which the container does not allow", t);
            return 1;
        }
    }
    if (again) {
        fail(k, "its discrete states still need an update after 100 calls of fmi3UpdateDiscreteStates at t = %.17g", t);
        return 1;
    }
    status = ((fmi3EnterStepModeTYPE *)k->f[F_ENTER_STEP])(k->instance);
    return call_failed(k, "fmi3EnterStepMode", status, t);
}

/* Runs internal steps 0 .. n-1 on c->grid (n = 0: the connections only, no doStep); 0 when they
 * all ran, 1 (logged) on failure, -1 when a component asked to end the simulation in internal
 * step j: the other components then complete step j (Jacobi), the connected outputs are read
 * (the connected inputs are not set: a component that said Discard accepts no input), and
 * *reached is the earliest time a component that asked reached (t_j + h when each completed
 * its step). */
static int run_loop(Instance *inst, long n, double *reached)
{
    Container *c = (Container *)inst->model_data;
    long k_failed = 0;
    int op = 0, status = 0, rc, ended = 0;
    if (n == 0)
        rc = duffid_cosim_run(c->grid, 0, 1, 0.0, c->init_stages, 2, c->sets, c->steps, c->gets, c->posts, NULL, 0,
                              stop_on_step, &k_failed, &op, &status);
    else
        rc = duffid_cosim_run(c->grid, 0, n, CONTAINER_STEP, c->stages, 2, c->sets, c->steps, c->gets, c->posts,
                              NULL, 0, stop_on_step, &k_failed, &op, &status);
    while (rc == DUFFID_LOOP_ABORTED) {
        const long j = k_failed;
        const double t = c->grid[j];
        Component *k = &c->comps[op];
        double r;
        duffid_stage rest, after[2];
        if (k->info->event_mode && status <= 1 && !k->terminate &&
            k->event_handling_needed) {
            /* its events, then the rest of internal step j (later doSteps, gets; the sets unless a component
             * asked to end), then the internal steps after it */
            if (handle_events(k, t + CONTAINER_STEP, 0)) return 1;
            memset(after, 0, sizeof after);
            after[0].step_lo = op + 1;
            after[0].step_hi = N_COMPONENTS;
            after[0].get_hi = c->n_gets;
            after[0].post_hi = c->n_posts;
            after[1].set_hi = c->n_sets;
            rc = duffid_cosim_run(c->grid, j, j + 1, CONTAINER_STEP, after, ended ? 1 : 2, c->sets, c->steps, c->gets,
                                  c->posts, NULL, 0, stop_on_step, &k_failed, &op, &status);
            if (rc == DUFFID_LOOP_DONE && !ended && j + 1 < n)
                rc = duffid_cosim_run(c->grid, j + 1, n, CONTAINER_STEP, c->stages, 2, c->sets, c->steps, c->gets,
                                      c->posts, NULL, 0, stop_on_step, &k_failed, &op, &status);
            continue;
        }
        if (!asked_to_end(k, status, t, &r)) {
            loop_failed(c, rc, op, status, k_failed, n);
            return 1;
        }
        fmu_log(inst, FMU_DISCARD, "logStatusDiscard", "component '%s' (%s, %s) asked to end the simulation at "
                "t = %.17g (in the internal step from t = %.17g): the container ends there", k->info->name,
                k->info->fmu, component_kind(k), r, t);
        *reached = ended ? fmin(*reached, r) : r;
        ended = 1;
        /* the rest of internal step j: the later components' doSteps, then every get */
        memset(&rest, 0, sizeof rest);
        rest.step_lo = op + 1;
        rest.step_hi = N_COMPONENTS;
        rest.get_hi = c->n_gets;
        rest.post_hi = c->n_posts;
        rc = duffid_cosim_run(c->grid, j, j + 1, CONTAINER_STEP, &rest, 1, c->sets, c->steps, c->gets, c->posts,
                              NULL, 0, stop_on_step, &k_failed, &op, &status);
    }
    if (rc == DUFFID_LOOP_DONE) return ended ? -1 : 0;
    loop_failed(c, rc, op, status, k_failed, n);
    return 1;
}

/* ------------------------------------------------------------------ model functions */

static void free_data(Instance *inst)
{
    Container *c = (Container *)inst->model_data;
    int i;
    if (c == NULL) return;
    for (i = 0; i < N_COMPONENTS; i++) {
        Component *k = &c->comps[i];
        if (k->instance != NULL && k->f[F_FREE] != NULL) {
            if (k->info->fmi_version == 2)
                ((fmi2FreeInstanceTYPE *)k->f[F_FREE])(k->instance);
            else
                ((fmi3FreeInstanceTYPE *)k->f[F_FREE])(k->instance);
        }
        k->instance = NULL;
        if (k->library != NULL) close_library(k->library);
        k->library = NULL;
    }
    free(c->sets);
    free(c->gets);
    free(c->posts);
    free(c->set_component);
    free(c->get_component);
    for (i = 0; i < CONTAINER_N_KINDS; i++) {
        size_t j;
        for (j = 0; c->values[i] != NULL && j < c->count[i]; j++) {
            if (i == CONTAINER_KIND_STRING) free(((char **)c->values[i])[j]);
            if (i == CONTAINER_KIND_BINARY) free(((ContainerBinary *)c->values[i])[j].data);
        }
        free(c->values[i]);
    }
    for (i = 0; c->object_ops != NULL && i < c->n_object_ops; i++) {
        free(c->object_ops[i].pointers);
        free(c->object_ops[i].sizes);
    }
    free(c->object_ops);
    free(c->staging);
    free(c->set_values);
    free(c->source_vr);
    free(c->target_vr);
    free(c->set_kind);
    free(c->get_kind);
    free(c->sent);
    free(c->sent_valid);
    free(c->grid);
    free(c);
    inst->model_data = NULL;
}

static int instantiate(Instance *inst)
{
    Container *c;
    char *folder;
    int i;
    if (inst->kind != KIND_CO_SIMULATION) {
        fmu_log(inst, FMU_ERROR, "logStatusError", "the container is a co-simulation FMU only");
        return 1;
    }
    folder = resource_folder(inst);
    if (folder == NULL) return 1;
    c = (Container *)calloc(1, sizeof(Container));
    if (c == NULL) {
        free(folder);
        fmu_log(inst, FMU_ERROR, "logStatusError", "out of memory");
        return 1;
    }
    inst->model_data = c;
    c->sent = (double *)calloc(CONTAINER_N_VARS, sizeof(double));
    c->sent_valid = (unsigned char *)calloc(CONTAINER_N_VARS, 1);
    c->grid_size = 2;
    c->grid = (double *)calloc((size_t)c->grid_size, sizeof(double));
    if (c->sent == NULL || c->sent_valid == NULL || c->grid == NULL) {
        free(folder);
        fmu_log(inst, FMU_ERROR, "logStatusError", "out of memory");
        return 1; /* free_data releases the rest */
    }
    for (i = 0; i < N_COMPONENTS; i++) {
        c->comps[i].info = &container_components[i];
        c->comps[i].owner = inst;
    }
    for (i = 0; i < N_COMPONENTS; i++) {
        if (load_component(inst, &c->comps[i], folder) != 0) {
            free(folder);
            return 1;
        }
    }
    free(folder);
    if (build_ops(c) != 0) {
        fmu_log(inst, FMU_ERROR, "logStatusError", "out of memory");
        return 1;
    }
    return 0;
}

typedef int (*set4_t)(void *, const unsigned *, size_t, const void *);
typedef int (*set5_t)(void *, const unsigned *, size_t, const void *, size_t);

/* Sets component k's parameter values fixed in the container, the structural ones (in Configuration
 * Mode, FMI 3) or the others; nonzero (logged) on failure. */
static int apply_settings(Component *k, int index, int structural)
{
    size_t i;
    int entered = 0, status;
    for (i = 0; i < CONTAINER_N_SETTINGS; i++) {
        const ContainerSetting *s = &container_settings[i];
        const duffid_function f = k->io[s->kind][1];
        if (s->component != index || s->structural != structural) continue;
        if (structural && !entered) {
            status = ((fmi3EnterConfigurationModeTYPE *)k->f[F_ENTER_CONFIGURATION])(k->instance);
            if (call_failed(k, "fmi3EnterConfigurationMode", status, 0.0)) return 1;
            entered = 1;
        }
        if (s->kind == CONTAINER_KIND_BINARY)
            status = ((fmi3SetBinaryTYPE *)f)(k->instance, &s->vr, 1, s->sizes, (const fmi3Binary *)s->values,
                                             (size_t)s->n);
        else if (k->info->fmi_version == 3)
            status = ((set5_t)f)(k->instance, &s->vr, 1, s->values, (size_t)s->n);
        else
            status = ((set4_t)f)(k->instance, &s->vr, 1, s->values);
        if (status > 1) {
            fail(k, "%s of %s (a value fixed in the container) returned %s",
                 container_set_names[k->info->fmi_version - 2][s->kind], s->name, status_name(status));
            return 1;
        }
    }
    if (entered) {
        status = ((fmi3ExitConfigurationModeTYPE *)k->f[F_EXIT_CONFIGURATION])(k->instance);
        if (call_failed(k, "fmi3ExitConfigurationMode", status, 0.0)) return 1;
    }
    return 0;
}

static int enter_initialization(Instance *inst)
{
    Container *c = (Container *)inst->model_data;
    int i, status;
    for (i = 0; i < N_COMPONENTS; i++) {
        Component *k = &c->comps[i];
        if (k->info->fmi_version == 2) {
            status = ((fmi2SetupExperimentTYPE *)k->f[F_SETUP])(k->instance, fmi2False, 0.0, inst->start_time,
                                                                inst->stop_time_defined ? fmi2True : fmi2False,
                                                                inst->stop_time);
            if (call_failed(k, "fmi2SetupExperiment", status, inst->start_time)) return 1;
        }
        if (apply_settings(k, i, 1) != 0 || apply_settings(k, i, 0) != 0) return 1;
    }
    if (pass_values(inst, CAUSALITY_PARAMETER, 1) != 0) return 1;
    for (i = 0; i < N_COMPONENTS; i++) {
        Component *k = &c->comps[i];
        if (k->info->fmi_version == 2)
            status = ((fmi2EnterInitializationModeTYPE *)k->f[F_ENTER])(k->instance);
        else
            status = ((fmi3EnterInitializationModeTYPE *)k->f[F_ENTER])(
                k->instance, fmi3False, 0.0, inst->start_time, inst->stop_time_defined ? fmi3True : fmi3False,
                inst->stop_time);
        if (call_failed(k, FUNCTION_NAMES[k->info->fmi_version - 2][F_ENTER], status, inst->start_time)) return 1;
        k->stage = STAGE_INITIALIZING;
    }
    /* connected inputs start from zeros (the orchestrator's value buffers before the first read) */
    c->grid[0] = inst->start_time;
    {
        long k_failed = 0;
        int op = 0, st = 0;
        duffid_stage sets_only[1];
        memset(sets_only, 0, sizeof sets_only);
        sets_only[0].set_hi = c->n_sets;
        if (duffid_cosim_run(c->grid, 0, 1, 0.0, sets_only, 1, c->sets, c->steps, c->gets, c->posts, NULL, 0,
                             stop_on_step, &k_failed, &op, &st) != DUFFID_LOOP_DONE) {
            Component *k = &c->comps[c->set_component[op]];
            fail(k, "setting its connected inputs in initialisation mode returned %s", status_name(st));
            return 1;
        }
    }
    return pass_values(inst, CAUSALITY_INPUT, 1);
}

static int exit_initialization(Instance *inst)
{
    Container *c = (Container *)inst->model_data;
    int i, status;
    if (pass_values(inst, CAUSALITY_PARAMETER, 0) != 0 || pass_values(inst, CAUSALITY_INPUT, 0) != 0) return 1;
    for (i = 0; i < N_COMPONENTS; i++) {
        Component *k = &c->comps[i];
        if (k->info->fmi_version == 2)
            status = ((fmi2ExitInitializationModeTYPE *)k->f[F_EXIT])(k->instance);
        else
            status = ((fmi3ExitInitializationModeTYPE *)k->f[F_EXIT])(k->instance);
        if (call_failed(k, FUNCTION_NAMES[k->info->fmi_version - 2][F_EXIT], status, inst->start_time)) return 1;
        /* FMI 3 with Event Mode leaves initialisation in Event Mode */
        if (k->info->event_mode && handle_events(k, inst->start_time, 1)) return 1;
        k->stage = STAGE_STEPPING;
    }
    c->grid[0] = inst->start_time;
    return run_loop(inst, 0, NULL) != 0; /* the connections' first values (no doStep: nothing can end) */
}

static int terminate(Instance *inst)
{
    Container *c = (Container *)inst->model_data;
    int i, failed = 0;
    for (i = 0; c != NULL && i < N_COMPONENTS; i++) {
        Component *k = &c->comps[i];
        int status;
        if (k->stage != STAGE_STEPPING) continue;
        if (k->info->fmi_version == 2)
            status = ((fmi2TerminateTYPE *)k->f[F_TERMINATE])(k->instance);
        else
            status = ((fmi3TerminateTYPE *)k->f[F_TERMINATE])(k->instance);
        failed |= call_failed(k, FUNCTION_NAMES[k->info->fmi_version - 2][F_TERMINATE], status, inst->time);
        k->stage = STAGE_TERMINATED;
    }
    return failed;
}

/* The container's outputs from its components (time: the container's). In Step Failed,
 * Terminated and Error the components are not asked: the values stay those last computed. */
static int evaluate(Instance *inst)
{
    Container *c = (Container *)inst->model_data;
    inst->vars[TIME_VR] = inst->time;
    if (!(inst->mode & (MODE_INITIALIZATION | MODE_STEP))) return 0;
    if (c == NULL) return 1;
    if (pass_values(inst, CAUSALITY_PARAMETER, 0) != 0 || pass_values(inst, CAUSALITY_INPUT, 0) != 0) return 1;
    return read_outputs(inst);
}

static int do_step(Instance *inst, double t, double h)
{
    Container *c = (Container *)inst->model_data;
    double n_real = h / CONTAINER_STEP, k_real = (t - inst->start_time) / CONTAINER_STEP, reached = t;
    long n, k0, j;
    int rc;
    if (c == NULL) return 1;
    n = (long)floor(n_real + 0.5);
    k0 = (long)floor(k_real + 0.5);
    if (n < 1 || fabs((double)n * CONTAINER_STEP - h) > 1e-9 * h) {
        fmu_log(inst, FMU_ERROR, "logStatusError", "fmi2DoStep: communicationStepSize %.17g is not a whole "
                "multiple of the container's internal step %.17g", h, CONTAINER_STEP);
        return 1;
    }
    if (k0 < 0 || fabs(inst->start_time + (double)k0 * CONTAINER_STEP - t) > 1e-9 * fmax(CONTAINER_STEP, fabs(t))) {
        fmu_log(inst, FMU_ERROR, "logStatusError", "fmi2DoStep: currentCommunicationPoint %.17g is not on the "
                "container's grid start + k * %.17g (start %.17g)", t, CONTAINER_STEP, inst->start_time);
        return 1;
    }
    if (n + 1 > c->grid_size) {
        double *grid = (double *)realloc(c->grid, (size_t)(n + 1) * sizeof(double));
        if (grid == NULL) {
            fmu_log(inst, FMU_ERROR, "logStatusError", "out of memory");
            return 1;
        }
        c->grid = grid;
        c->grid_size = n + 1;
    }
    for (j = 0; j <= n; j++) c->grid[j] = inst->start_time + (double)(k0 + j) * CONTAINER_STEP;
    if (pass_values(inst, CAUSALITY_INPUT, 0) != 0) return 1;
    rc = run_loop(inst, n, &reached);
    if (rc < 0) { /* a component asked to end the simulation: so does the container, at that time */
        fmu_request_termination(inst, reached);
        return 0;
    }
    return rc;
}

const ModelInfo fmu_model_info = {
    .model_identifier = CONTAINER_IDENTIFIER,
    .instantiation_token = CONTAINER_TOKEN,
    .n_vars = CONTAINER_N_VARS,
    .names = container_names,
    .start = container_start,
    .causality = container_causality,
    .variability = container_variability,
    .settable_start = container_settable_start,
    .n_states = 0,
    .evaluate = evaluate,
    .do_step = do_step,
    .default_tolerance = 1e-8,
    .interfaces = INTERFACE_CO_SIMULATION,
    .free_data = free_data,
    .non_finite_outputs = 1,
    .types = container_types,
    .instantiate = instantiate,
    .enter_initialization = enter_initialization,
    .exit_initialization = exit_initialization,
    .terminate = terminate,
    .no_fmu_state = 1,
};
