/*
 * insn_plugin.c - a QEMU TCG plugin (QEMU 7.2, plugin API version 1) that counts executed
 * guest instructions per duffid_update of the embedded test program.
 *
 * Arguments (-plugin ./insn_plugin.so,begin=ADDR,end=ADDR,out=FILE):
 *   begin, end  addresses of embedded_mark_begin / embedded_mark_end (from nm; the Thumb
 *               bit is ignored);
 *   out         the result file.
 *
 * Every translated block gets an execution callback that adds the block's instruction count
 * to a running total and, while inside an update (between a begin and an end marker), one
 * execution to the block's own counter. The markers' first instructions get an instruction
 * callback that records the total. Result file:
 *   update INDEX INSTRUCTIONS      one per begin/end pair (total at end minus total at
 *                                  begin: the update, its call sequence and one marker body)
 *   block VADDR NINSNS EXECS       per translated block executed inside updates (a block
 *                                  translated twice appears twice)
 *   total INSTRUCTIONS             the whole run
 * Functions are resolved from the block addresses by benchmarks/embedded.py (nm).
 *
 * The QEMU 7.2 plugin API is declared here (no qemu-plugin.h is installed): only what this
 * plugin uses, with the types and signatures that API version 1 documents.
 */
#include <inttypes.h>
#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

/* ---- minimal declarations of the QEMU plugin API (version 1) ---------------------------- */
#define PLUGIN_EXPORT __attribute__((visibility("default")))
typedef uint64_t qemu_plugin_id_t;
struct qemu_plugin_tb;
struct qemu_plugin_insn;
typedef struct {
    const char *target_name;
    struct {
        int min;
        int cur;
    } version;
    bool system_emulation;
    union {
        struct {
            int smp_vcpus;
            int max_vcpus;
        } system;
    } u;
} plugin_info;
enum plugin_cb_flags { PLUGIN_CB_NO_REGS = 0 };
typedef void (*plugin_udata_cb)(qemu_plugin_id_t id, void *userdata);
typedef void (*plugin_vcpu_udata_cb)(unsigned int vcpu_index, void *userdata);
typedef void (*plugin_tb_trans_cb)(qemu_plugin_id_t id, struct qemu_plugin_tb *tb);

void qemu_plugin_register_vcpu_tb_trans_cb(qemu_plugin_id_t id, plugin_tb_trans_cb cb);
void qemu_plugin_register_vcpu_tb_exec_cb(struct qemu_plugin_tb *tb, plugin_vcpu_udata_cb cb,
                                          enum plugin_cb_flags flags, void *userdata);
void qemu_plugin_register_vcpu_insn_exec_cb(struct qemu_plugin_insn *insn, plugin_vcpu_udata_cb cb,
                                            enum plugin_cb_flags flags, void *userdata);
size_t qemu_plugin_tb_n_insns(const struct qemu_plugin_tb *tb);
uint64_t qemu_plugin_tb_vaddr(const struct qemu_plugin_tb *tb);
struct qemu_plugin_insn *qemu_plugin_tb_get_insn(const struct qemu_plugin_tb *tb, size_t idx);
uint64_t qemu_plugin_insn_vaddr(const struct qemu_plugin_insn *insn);
void qemu_plugin_register_atexit_cb(qemu_plugin_id_t id, plugin_udata_cb cb, void *userdata);
void qemu_plugin_outs(const char *string);

PLUGIN_EXPORT extern int qemu_plugin_version;
PLUGIN_EXPORT int qemu_plugin_version = 1;
PLUGIN_EXPORT int qemu_plugin_install(qemu_plugin_id_t id, const plugin_info *info, int argc, char **argv);

/* ---- state (one vCPU: callbacks never run concurrently) --------------------------------- */
struct block {
    uint64_t vaddr;
    uint64_t n_insns;
    uint64_t execs_inside;
};

static uint64_t begin_addr = UINT64_MAX, end_addr = UINT64_MAX;
static char out_path[4096];
static uint64_t total;          /* instructions executed so far */
static uint64_t update_start;   /* total at the latest begin marker */
static int inside;              /* between a begin and an end marker */
static struct block **blocks;   /* every translated block */
static size_t n_blocks, cap_blocks;
static uint64_t *updates;       /* instructions per update */
static size_t n_updates, cap_updates;
static uint64_t unmatched;      /* markers out of order */

static void *grow(void *p, size_t *cap, size_t item)
{
    size_t n = *cap ? 2 * *cap : 1024;
    void *q = realloc(p, n * item);
    if (q == NULL) {
        qemu_plugin_outs("insn_plugin: out of memory\n");
        abort();
    }
    *cap = n;
    return q;
}

static void on_block(unsigned int vcpu, void *userdata)
{
    struct block *b = userdata;
    (void)vcpu;
    total += b->n_insns;
    if (inside) {
        b->execs_inside++;
    }
}

static void on_begin(unsigned int vcpu, void *userdata)
{
    (void)vcpu;
    (void)userdata;
    if (inside) {
        unmatched++;
    }
    inside = 1;
    update_start = total;
}

static void on_end(unsigned int vcpu, void *userdata)
{
    (void)vcpu;
    (void)userdata;
    if (!inside) {
        unmatched++;
        return;
    }
    inside = 0;
    if (n_updates == cap_updates) {
        updates = grow(updates, &cap_updates, sizeof *updates);
    }
    updates[n_updates++] = total - update_start;
}

static void on_translate(qemu_plugin_id_t id, struct qemu_plugin_tb *tb)
{
    size_t i, n = qemu_plugin_tb_n_insns(tb);
    struct block *b = calloc(1, sizeof *b);
    (void)id;
    if (b == NULL) {
        qemu_plugin_outs("insn_plugin: out of memory\n");
        abort();
    }
    b->vaddr = qemu_plugin_tb_vaddr(tb);
    b->n_insns = n;
    if (n_blocks == cap_blocks) {
        blocks = grow(blocks, &cap_blocks, sizeof *blocks);
    }
    blocks[n_blocks++] = b;
    /* the block's callback first, so a marker sees its own block counted */
    qemu_plugin_register_vcpu_tb_exec_cb(tb, on_block, PLUGIN_CB_NO_REGS, b);
    for (i = 0; i < n; i++) {
        struct qemu_plugin_insn *insn = qemu_plugin_tb_get_insn(tb, i);
        uint64_t a = qemu_plugin_insn_vaddr(insn) & ~(uint64_t)1;
        if (a == begin_addr) {
            qemu_plugin_register_vcpu_insn_exec_cb(insn, on_begin, PLUGIN_CB_NO_REGS, NULL);
        } else if (a == end_addr) {
            qemu_plugin_register_vcpu_insn_exec_cb(insn, on_end, PLUGIN_CB_NO_REGS, NULL);
        }
    }
}

static void on_exit_(qemu_plugin_id_t id, void *userdata)
{
    FILE *out;
    size_t i;
    char msg[256];
    (void)id;
    (void)userdata;
    out = fopen(out_path, "w");
    if (out == NULL) {
        snprintf(msg, sizeof msg, "insn_plugin: cannot write %.200s\n", out_path);
        qemu_plugin_outs(msg);
        return;
    }
    for (i = 0; i < n_updates; i++) {
        fprintf(out, "update %zu %" PRIu64 "\n", i, updates[i]);
    }
    for (i = 0; i < n_blocks; i++) {
        if (blocks[i]->execs_inside != 0) {
            fprintf(out, "block %" PRIx64 " %" PRIu64 " %" PRIu64 "\n", blocks[i]->vaddr,
                    blocks[i]->n_insns, blocks[i]->execs_inside);
        }
    }
    fprintf(out, "unmatched %" PRIu64 "\n", unmatched);
    fprintf(out, "total %" PRIu64 "\n", total);
    fclose(out);
}

int qemu_plugin_install(qemu_plugin_id_t id, const plugin_info *info, int argc, char **argv)
{
    int i;
    (void)info;
    for (i = 0; i < argc; i++) {
        const char *a = argv[i];
        if (strncmp(a, "begin=", 6) == 0) {
            begin_addr = strtoull(a + 6, NULL, 0) & ~(uint64_t)1;
        } else if (strncmp(a, "end=", 4) == 0) {
            end_addr = strtoull(a + 4, NULL, 0) & ~(uint64_t)1;
        } else if (strncmp(a, "out=", 4) == 0) {
            snprintf(out_path, sizeof out_path, "%s", a + 4);
        } else {
            char msg[256];
            snprintf(msg, sizeof msg, "insn_plugin: unknown argument %s\n", a);
            qemu_plugin_outs(msg);
            return -1;
        }
    }
    if (begin_addr == UINT64_MAX || end_addr == UINT64_MAX || out_path[0] == '\0') {
        qemu_plugin_outs("insn_plugin: need begin=ADDR,end=ADDR,out=FILE\n");
        return -1;
    }
    qemu_plugin_register_vcpu_tb_trans_cb(id, on_translate);
    qemu_plugin_register_atexit_cb(id, on_exit_, NULL);
    return 0;
}
