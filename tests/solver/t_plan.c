/*
 * t_plan.c - the plan of a job (solver/mpm_plan.h): what the solver
 * chooses for each family (the text of mpm_sim_plan() for disks of every
 * method and transfer, portable and AVX2 kernels, a Drucker-Prager box),
 * that the text read back through mpm_sim_plan_override() is the same
 * plan, that an override refuses what the job cannot run naming the key,
 * and that the variants that keep the bits (fuse off, auto, always; the
 * sort's ring) keep them while kernels=portable gives the portable case's
 * bits.
 */
#include "mpm_diag.h"
#include "mpm_paper.h"
#include "t.h"

#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

static mpm_sim *disks(mpm_method m, mpm_update up, mpm_transfer tr, double pic, mpm_kernels_isa k,
                      int threads)
{
    mpm_paper t;
    mpm_paper_disks(&t, m, up, 0.05);
    t.c.transfer = tr;
    t.c.pic_fraction = pic;
    t.c.kernels = k;
    t.c.threads = threads;
    mpm_error err;
    mpm_sim *s = mpm_sim_new(&t.c, NULL, &err);
    mpm_paper_free(&t);
    return s;
}

/* value of key in a plan's text into out ("" when absent) */
static void val(const char *text, const char *key, char *out, size_t n)
{
    size_t k = strlen(key);
    out[0] = '\0';
    for (const char *a = text; (a = strstr(a, key)); a++)
        if ((a == text || a[-1] == ' ') && a[k] == '=') {
            snprintf(out, n, "%.*s", (int)strcspn(a + k + 1, " "), a + k + 1);
            return;
        }
}

TEST(plan_text_round_trip)
{
    static const struct {
        mpm_method m;
        mpm_update up;
        mpm_transfer tr;
        double pic;
        const char *want; /* key=value pairs the plan must hold */
    } cs[] = {
        {MPM_METHOD_MPM, MPM_USF, MPM_TRANSFER_FLIP, 0,
         "dim=2 shape=tent ns=2 transfer=flip block=direct gvel=1 fuse=auto trun=1 rows4=0"},
        {MPM_METHOD_MPM, MPM_MUSL, MPM_TRANSFER_APIC, 0,
         "shape=tent transfer=apic trun=0 tlanes_x=0"},
        {MPM_METHOD_GIMP, MPM_USL, MPM_TRANSFER_FLIP, 0.25,
         "shape=gimp ns=3 transfer=blend trun=0 tlanes=0 el_lanes=0"},
        {MPM_METHOD_BSPLINE2, MPM_MUSL, MPM_TRANSFER_FLIP, 0, "shape=bspline ns=3 tlanes=0"},
        {MPM_METHOD_BSPLINE3, MPM_USF, MPM_TRANSFER_APIC, 0, "shape=bspline ns=4 transfer=apic"},
        {MPM_METHOD_CPDI, MPM_USL, MPM_TRANSFER_FLIP, 0,
         "kernels=portable fma=0 shape=cpdi gvel=0 fuse=off trun=0 tlanes=0 rows4=0"},
    };
    int avx2 = mpm_kernels_avx2_available();
    for (size_t i = 0; i < sizeof cs / sizeof *cs; i++)
        for (int port = 0; port < 2; port++) {
            mpm_sim *s = disks(cs[i].m, cs[i].up, cs[i].tr, cs[i].pic,
                               port ? MPM_KERNELS_PORTABLE : MPM_KERNELS_AUTO, 1);
            CHECKF(s, "case %zu", i);
            char text[MPM_PLAN_LEN], again[MPM_PLAN_LEN], want[64], got[64];
            int len = mpm_sim_plan(s, text, sizeof text);
            CHECK(len > 0 && (size_t)len < sizeof text && strlen(text) == (size_t)len);
            TLOG("%s %s: %s", mpm_method_key(cs[i].m), port ? "portable" : "auto", text);
            /* the case's own facts */
            char kw[256];
            snprintf(kw, sizeof kw, "%s", cs[i].want);
            for (char *tok = strtok(kw, " "); tok; tok = strtok(NULL, " ")) {
                char *eq = strchr(tok, '=');
                CHECKF(eq, "case %zu: '%s' in the test's table", i, tok);
                *eq = '\0';
                val(text, tok, got, sizeof got);
                CHECKF(!strcmp(got, eq + 1), "case %zu: %s=%s, want %s", i, tok, got, eq + 1);
            }
            int on = avx2 && !port && cs[i].m != MPM_METHOD_CPDI;
            val(text, "kernels", got, sizeof got);
            CHECKF(!strcmp(got, on ? "avx2" : "portable"), "case %zu: kernels=%s", i, got);
            CHECK(!strcmp(mpm_sim_kernels(s), on ? "avx2-fma" : "portable"));
            snprintf(want, sizeof want, "%d", on && cs[i].m == MPM_METHOD_MPM);
            val(text, "tlanes", got, sizeof got);
            CHECKF(!strcmp(got, want), "case %zu: tlanes=%s", i, got);
            /* the whole text back: accepted, nothing changes */
            mpm_error err;
            CHECKF(mpm_sim_plan_override(s, text, &err) == 0, "case %zu: %s", i, TERR(&err));
            mpm_sim_plan(s, again, sizeof again);
            CHECKF(!strcmp(text, again), "case %zu: %s became %s", i, text, again);
            /* a short buffer: truncated, the length still the whole */
            char small[8];
            CHECK(mpm_sim_plan(s, small, sizeof small) == len && strlen(small) == 7);
            mpm_sim_destroy(&s);
        }
}

/* One refused override: its code and field, the plan unchanged. */
static int refused(mpm_sim *s, const char *text, const char *field)
{
    char before[MPM_PLAN_LEN], after[MPM_PLAN_LEN];
    mpm_sim_plan(s, before, sizeof before);
    mpm_error err;
    char f[64];
    int rc = mpm_sim_plan_override(s, text, &err);
    mpm_sim_plan(s, after, sizeof after);
    mpm_error_field(&err, MPM_FIELD_PROTO, f, sizeof f);
    TLOG("'%s': %s", text, TERR(&err));
    return rc == MPM_EINVAL && !strcmp(f, field) && !strcmp(before, after);
}

TEST(plan_override_refuses)
{
    mpm_sim *s = disks(MPM_METHOD_MPM, MPM_USF, MPM_TRANSFER_FLIP, 0, MPM_KERNELS_AUTO, 1);
    CHECK(s);
    CHECK(refused(s, "colour=blue", "plan"));
    CHECK(refused(s, "fuse", "plan"));
    CHECK(refused(s, "fuse=sometimes", "plan"));
    CHECK(refused(s, "sort_ring=-1", "plan"));
    CHECK(refused(s, "dim=3", "plan"));      /* derived */
    CHECK(refused(s, "shape=gimp", "plan")); /* derived */
    CHECK(refused(s, "ns=3", "plan.ns"));    /* tents have 2 */
    CHECK(refused(s, "sort_ring=3", "plan.sort_ring"));
    CHECK(refused(s, "sort_ring=1048576", "plan.sort_ring")); /* more than allocated */
    CHECK(refused(s, "dp_lanes=1", "plan.dp_lanes"));         /* no Drucker-Prager */
    CHECK(refused(s, "kernels=portable el_lanes=1", "plan.el_lanes"));
    if (!mpm_kernels_avx2_available()) CHECK(refused(s, "kernels=avx2", "plan.kernels"));
    CHECK(mpm_sim_step(s) == 0);
    mpm_sim_destroy(&s);

    s = disks(MPM_METHOD_CPDI, MPM_USF, MPM_TRANSFER_FLIP, 0, MPM_KERNELS_AUTO, 1);
    CHECK(s);
    CHECK(refused(s, "fuse=always", "plan.fuse"));
    CHECK(refused(s, "kernels=avx2", "plan.kernels"));
    mpm_sim_destroy(&s);

    s = disks(MPM_METHOD_GIMP, MPM_USF, MPM_TRANSFER_FLIP, 0, MPM_KERNELS_AUTO, 1);
    CHECK(s);
    CHECK(mpm_sim_step(s) == 0);
    CHECK(refused(s, "ns=4", "plan.ns")); /* only before the first step */
    mpm_sim_destroy(&s);
    mpm_error err;
    CHECK(mpm_sim_plan_override(NULL, "", &err) == MPM_EINVAL);
}

/* FNV-1a of positions, velocities and stresses after steps steps */
static int run_hash(mpm_sim *s, int steps, uint64_t *h)
{
    if (!s) return -1;
    int rc = mpm_sim_run(s, steps);
    size_t n = mpm_sim_particles(s);
    double *buf = calloc(n * 10, sizeof *buf);
    if (!buf) return -1;
    mpm_sim_snapshot(s, &(mpm_snapshot){.x = buf, .v = buf + 2 * n, .stress = buf + 4 * n});
    uint64_t k = 1469598103934665603ull;
    const unsigned char *b = (const unsigned char *)buf;
    for (size_t i = 0; i < n * 10 * sizeof *buf; i++) k = (k ^ b[i]) * 1099511628211ull;
    *h = k;
    free(buf);
    return rc;
}

TEST(plan_variants_same_bits)
{
    static const char *const same[] = {"", "fuse=off", "fuse=always", "fuse=auto sort_ring=2"};
    for (int m = 0; m < 3; m++) {
        mpm_method meth = m == 0 ? MPM_METHOD_MPM : m == 1 ? MPM_METHOD_GIMP : MPM_METHOD_BSPLINE2;
        for (int up = 0; up < 3; up += 2) {
            uint64_t h[4], hp = 0, hq = 1;
            for (int v = 0; v < 4; v++) {
                mpm_sim *s = disks(meth, (mpm_update)up, MPM_TRANSFER_FLIP, 0, MPM_KERNELS_AUTO, 2);
                mpm_error err;
                CHECKF(s && mpm_sim_plan_override(s, same[v], &err) == 0, "%s", TERR(&err));
                CHECK(run_hash(s, 60, &h[v]) == 0);
                mpm_sim_destroy(&s);
                CHECKF(h[v] == h[0], "%s %s '%s': %016llx, default %016llx", mpm_method_key(meth),
                       mpm_update_key((mpm_update)up), same[v], (unsigned long long)h[v],
                       (unsigned long long)h[0]);
            }
            /* kernels=portable by the plan is the portable case */
            mpm_sim *s = disks(meth, (mpm_update)up, MPM_TRANSFER_FLIP, 0, MPM_KERNELS_PORTABLE, 2);
            CHECK(run_hash(s, 60, &hp) == 0);
            mpm_sim_destroy(&s);
            s = disks(meth, (mpm_update)up, MPM_TRANSFER_FLIP, 0, MPM_KERNELS_AUTO, 2);
            CHECK(s && mpm_sim_plan_override(s, "kernels=portable", NULL) == 0);
            CHECK(!strcmp(mpm_sim_kernels(s), "portable"));
            CHECK(run_hash(s, 60, &hq) == 0);
            mpm_sim_destroy(&s);
            CHECKF(hp == hq, "%s %s: kernels=portable %016llx, the portable case %016llx",
                   mpm_method_key(meth), mpm_update_key((mpm_update)up), (unsigned long long)hq,
                   (unsigned long long)hp);
            TLOG("%s %s: %016llx (4 variants), portable %016llx", mpm_method_key(meth),
                 mpm_update_key((mpm_update)up), (unsigned long long)h[0], (unsigned long long)hp);
        }
    }
}
