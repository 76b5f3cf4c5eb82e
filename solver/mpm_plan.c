/*
 * mpm_plan.c - the plan of a job (mpm_plan.h): its defaults from the case
 * and the CPU (mpm_plan_choose()), and its text form, one table of keys
 * (plan_keys[]) for the printer and the parser.  mpm_sim.c makes the plan
 * at creation and applies overrides (mpm_sim_plan_override()); the step
 * and the kernels read mpm_sim.plan.  Tests: plan_text_round_trip,
 * plan_override_refuses, and the same-bits tests that force variants
 * through it (fuse_, perf_el_lanes_same_bits, sort_ring).
 */
#include "mpm_plan.h"
#include "mpm_kernels_avx2.h"

#include "mpm_internal.h"
#include "mpm_material_table.h"

#include <stdio.h>
#include <string.h>

/* The keys, in the order of the text.  vals: the names of the values 0,
 * 1, ... ("|"-separated), or NULL for a number. */
typedef struct {
    const char *key;
    size_t off;
    int chosen;
    const char *vals;
} plan_key;

#define PK(k, f, ch, v)                 \
    {                                   \
        k, offsetof(mpm_plan, f), ch, v \
    }
static const plan_key plan_keys[] = {
    PK("kernels", avx2, 1, "portable|avx2"),
    PK("fma", fma, 0, "0|1"),
    PK("dim", dim, 0, NULL),
    PK("shape", family, 0, "tent|gimp|bspline|cpdi"),
    PK("ns", ns, 1, NULL),
    PK("transfer", variant, 0, "flip|blend|apic"),
    PK("block", general, 0, "direct|general"),
    PK("gvel", gvel, 0, "0|1"),
    PK("fuse", fuse, 1, "off|auto|always"),
    PK("trun", trun, 0, "0|1"),
    PK("tlanes", tlanes, 0, "0|1"),
    PK("tlanes_x", tlanes_x, 0, "0|1"),
    PK("rows4", rows4, 0, "0|1"),
    PK("el_lanes", el_lanes, 1, "0|1"),
    PK("dp_lanes", dp_lanes, 1, "0|1"),
    PK("sort_ring", sort_ring, 1, NULL),
};
#define NKEYS (sizeof plan_keys / sizeof plan_keys[0])
_Static_assert(NKEYS <= 32, "mpm_plan_parse()'s given is a 32-bit mask");

static int *field(mpm_plan *p, const plan_key *k)
{
    return (int *)((char *)p + k->off);
}

/* value v's name in vals ("a|b|c") into out (n bytes); 0, or -1 when
 * vals has no value v */
static int val_name(const char *vals, int v, char *out, size_t n)
{
    const char *a = vals;
    for (int i = 0; i < v && a; i++) {
        a = strchr(a, '|');
        if (a) a++;
    }
    if (!a || v < 0) return -1;
    size_t len = strcspn(a, "|");
    snprintf(out, n, "%.*s", (int)len, a);
    return 0;
}

int mpm_plan_format(const mpm_plan *p, char *buf, size_t n)
{
    size_t len = 0;
    for (size_t i = 0; i < NKEYS; i++) {
        const plan_key *k = &plan_keys[i];
        int v = *field((mpm_plan *)p, k);
        char name[16];
        if (!k->vals || val_name(k->vals, v, name, sizeof name))
            snprintf(name, sizeof name, "%d", v);
        int w = snprintf(len < n ? buf + len : NULL, len < n ? n - len : 0, "%s%s=%s", i ? " " : "",
                         k->key, name);
        if (w < 0) return w;
        len += (size_t)w;
    }
    if (n && len >= n) buf[n - 1] = '\0';
    return (int)len;
}

static const plan_key *find_key(const char *key, size_t len)
{
    for (size_t i = 0; i < NKEYS; i++)
        if (strlen(plan_keys[i].key) == len && !strncmp(plan_keys[i].key, key, len))
            return &plan_keys[i];
    return NULL;
}

unsigned mpm_plan_key_bit(const char *key)
{
    const plan_key *k = find_key(key, strlen(key));
    return k ? 1u << (k - plan_keys) : 0;
}

int mpm_plan_key_chosen(const char *key)
{
    const plan_key *k = find_key(key, strlen(key));
    return k && k->chosen;
}

int mpm_plan_value(const mpm_plan *p, unsigned b)
{
    return b < NKEYS ? *field((mpm_plan *)p, &plan_keys[b]) : 0;
}

const char *mpm_plan_key_name(unsigned b)
{
    return b < NKEYS ? plan_keys[b].key : NULL;
}

/* one value of k from v[0 .. len): its index in k->vals, or a decimal
 * number in [0, 2^30]; -1 when neither */
static int parse_val(const plan_key *k, const char *v, size_t len)
{
    if (k->vals) {
        char name[16];
        for (int i = 0; !val_name(k->vals, i, name, sizeof name); i++)
            if (strlen(name) == len && !strncmp(name, v, len)) return i;
        return -1;
    }
    if (len == 0 || len > 10) return -1;
    long x = 0;
    for (size_t i = 0; i < len; i++) {
        if (v[i] < '0' || v[i] > '9') return -1;
        x = x * 10 + (v[i] - '0');
    }
    return x <= (1L << 30) ? (int)x : -1;
}

int mpm_plan_parse(const char *text, mpm_plan *p, unsigned *given, mpm_error *err)
{
    mpm_plan q = *p;
    unsigned g = 0;
    const char *s = text ? text : "";
    for (;;) {
        s += strspn(s, " \t");
        if (!*s) break;
        size_t len = strcspn(s, " \t");
        const char *eq = memchr(s, '=', len);
        if (!eq)
            return mpm_fail(err, MPM_EINVAL, "plan", "expected key=value, got '%.*s'", (int)len, s);
        const plan_key *k = find_key(s, (size_t)(eq - s));
        if (!k) {
            char keys[320];
            size_t kl = 0;
            for (size_t i = 0; i < NKEYS && kl < sizeof keys; i++)
                kl += (size_t)snprintf(keys + kl, sizeof keys - kl, "%s%s", i ? ", " : "",
                                       plan_keys[i].key);
            return mpm_fail(err, MPM_EINVAL, "plan", "unknown key '%.*s' (keys: %s)", (int)(eq - s),
                            s, keys);
        }
        int v = parse_val(k, eq + 1, len - (size_t)(eq + 1 - s));
        if (v < 0)
            return mpm_fail(err, MPM_EINVAL, "plan", "%s: expected %s, got '%.*s'", k->key,
                            k->vals ? k->vals : "a number", (int)(len - (size_t)(eq + 1 - s)),
                            eq + 1);
        *field(&q, k) = v;
        g |= 1u << (k - plan_keys);
        s += len;
    }
    *p = q;
    if (given) *given = g;
    return 0;
}

int mpm_plan_gimp_fits3(const mpm_sim *s)
{
    for (int d = 0; d < s->dim; d++) {
        const double *lp = s->P.lp[d];
        double ih = s->inv_h[d];
        for (size_t p = 0; p < s->P.n; p++)
            if (!(lp[p] * ih <= 0.5)) return 0;
    }
    return 1;
}

void mpm_plan_choose(const mpm_sim *s, int allow_avx2, int ns_fixed, mpm_plan *p)
{
    int ns = p->ns;
    memset(p, 0, sizeof *p);
    int D = s->dim, cpdi = s->method == MPM_METHOD_CPDI;
    p->dim = D;
    p->family = cpdi                           ? MPM_FAM_CPDI
                : s->bsp                       ? MPM_FAM_BSPLINE
                : s->method == MPM_METHOD_GIMP ? MPM_FAM_GIMP
                                               : MPM_FAM_TENT;
    p->variant = s->transfer == MPM_TRANSFER_APIC ? MPM_VAR_APIC
                 : s->pic != 0                    ? MPM_VAR_BLEND
                                                  : MPM_VAR_FLIP;
    if (ns_fixed)
        p->ns = ns;
    else
        p->ns = p->family == MPM_FAM_GIMP ? (mpm_plan_gimp_fits3(s) ? 3 : 4)
                : s->bsp                  ? s->bsp + 1
                                          : 2;
    p->avx2 = allow_avx2 && !cpdi;
#ifdef MPM_HAVE_AVX2_KERNELS
    p->fma = p->avx2 && mpm_kernels_avx2_fuses();
#endif
    p->general = s->mixed || !s->model->update[0] || s->volmode != MPM_VOLUME_STRAIN_INCREMENT;
    p->gvel = !cpdi;
    p->fuse = cpdi ? MPM_FUSE_OFF : MPM_FUSE_AUTO;
    int apic = p->variant == MPM_VAR_APIC, tent = p->family == MPM_FAM_TENT;
    p->trun = tent && !apic;
    p->tlanes = p->avx2 && tent && D > 1;
    p->tlanes_x = p->tlanes && D > 2 && !apic;
    p->rows4 = p->avx2 && p->ns > 2 && !cpdi;
    /* the fused USF stress pass of tents by lanes: one linear elastic
     * material on the direct path, no strain record, and nothing else the
     * lanes would have to carry (2D: a sigma_zz array; 3D: spins) */
    p->el_lanes = p->tlanes && !p->general && s->nmat == 1 &&
                  s->mats[0].ops == mpm_model_get(MPM_MODEL_LINEAR_ELASTIC) && !s->P.eps[0] &&
                  (D == 2 ? !s->P.sig[2] : !s->spin3);
    for (size_t i = 0; i < s->nmat; i++)
        if (allow_avx2 && s->mats[i].pl && s->mats[i].pl->kind == MPM_PLASTIC_DRUCKER_PRAGER)
            p->dp_lanes = 1;
    int ring = 2;
    while ((size_t)ring < s->P.n && ring < MPM_SORT_RING) ring *= 2;
    p->sort_ring = ring;
}
