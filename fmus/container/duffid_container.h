/* The description of one container FMU, as the tables of its generated header
 * container_fmu_config.h (written by duffid.cosim.container): the components, the
 * connections between them and the mapping of the container's variables to theirs.
 *
 * The container's own variables (names, start values, causality, variability, types) are the
 * usual tables of the shared glue (fmus/common/fmu_model.h); value reference 0 is the time.
 * Their types are the glue's VARTYPE_* codes (Float64, Integer/Int32, Boolean); the connections
 * inside carry more kinds (below).
 */
#ifndef DUFFID_CONTAINER_H
#define DUFFID_CONTAINER_H

#include <stddef.h>
#include <stdint.h>

/* A component: an FMU unpacked in resources/<name>/ of the container. */
typedef struct {
    const char *name;              /* component name (and its folder in resources/) */
    const char *fmu;               /* the FMU file it came from, for messages */
    const char *model_identifier;  /* its binary: binaries/<platform>/<model_identifier><suffix> */
    int fmi_version;               /* 2 or 3 (co-simulation) */
    const char *token;             /* guid / instantiationToken */
    int event_mode;                /* FMI 3 hasEventMode: run with eventModeUsed, its events handled */
} ContainerComponent;

/* The connection sources, sorted by (component, kind): each a variable of n values (an array has
 * several) read after every internal step into slots slot .. slot + n - 1 of the buffer of its kind.
 * The kinds (Float64, Integer/Int32, Boolean, Float32, Int8 .. UInt64, Enumeration) and their FMI
 * functions are the generated tables container_buffer_size, container_get_names,
 * container_set_names and container_fmi_size (CONTAINER_N_KINDS). */
typedef struct {
    int component;
    unsigned vr;
    int kind;
    int slot;
    int n;
} ContainerSource;

/* The connection targets, sorted by (component, kind): each a variable of n values set after every
 * internal step (and from zeros during initialisation, as the orchestrator does) from the slots
 * container_target_slots[first .. first + n - 1] of the buffer of its kind. */
typedef struct {
    int component;
    unsigned vr;
    int kind;
    int first;
    int n;
} ContainerTarget;

/* A Binary value the container holds (its connections of FMI 3 Binary values copy them). */
typedef struct {
    size_t size;
    unsigned char *data;
} ContainerBinary;

/* A parameter value given to System.add that the container does not expose (a structural parameter,
 * an array, a type other than the glue's): set into its component before initialisation, a structural
 * one in Configuration Mode. values: n values as the FMI set function takes them (Binary: n pointers,
 * with their sizes). */
typedef struct {
    const char *name;              /* "component.parameter", for messages */
    int component;
    unsigned vr;
    int kind;
    int structural;
    int n;
    const void *values;
    const size_t *sizes;
} ContainerSetting;

/* A container variable and one component variable it maps to: an input or parameter is set
 * into each of its targets, an output read from its one source. */
typedef struct {
    unsigned container_vr;
    int component;
    unsigned vr;
} ContainerLink;

#endif
