/*
 * t_store_util.c - helpers shared by the store tests (see t_store.h).
 */
#include "t_store.h"

#include <float.h>
#include <math.h>
#include <stdio.h>
#include <string.h>

#include "t.h"

const unsigned char case_bytes[] = {0x0a, 0x04, 'b',  'a',  'r',  's',  0x00,
                                    0x10, 0x02, 0xff, 0x00, 0x7f, 0x80, 0x01};
const size_t case_bytes_len = sizeof case_bytes;

const char *db_path(const char *name)
{
    static char buf[512];
    snprintf(buf, sizeof buf, "%s/%s", t_tmpdir(), name);
    return buf;
}

void cap_log(void *ud, const char *msg)
{
    logcap *lc = ud;
    pthread_mutex_lock(&lc->mu);
    lc->n_total++;
    if (strstr(msg, "dropped")) lc->n_dropped++;
    if (strstr(msg, "above its cap")) lc->n_cap++;
    if (strstr(msg, "'interrupted'")) lc->n_interrupted++;
    if (strstr(msg, "new database, schema version")) lc->n_new++;
    if (strstr(msg, "schema migrated from version")) {
        lc->n_migrated++;
        snprintf(lc->migrated, sizeof lc->migrated, "%s", msg);
    }
    snprintf(lc->last, sizeof lc->last, "%s", msg);
    pthread_mutex_unlock(&lc->mu);
}

void quiet_log(void *ud, const char *msg)
{
    (void)ud;
    (void)msg;
}

store_run sample_run(const char *name, mpp_status st)
{
    store_run r;
    memset(&r, 0, sizeof r);
    r.name = name;
    r.case_pb = case_bytes;
    r.case_len = sizeof case_bytes;
    r.method = MPM_METHOD_GIMP;
    r.update = MPM_MUSL;
    r.dim = 2;
    r.particles = 12345;
    r.nodes = 678;
    r.status = st;
    r.submitted_at = 1700000000.25;
    r.server_version = "mpmd 0.1-test";
    return r;
}

/* A deterministic sample with awkward values; the same call gives the same
 * bits, so read-back can be compared exactly.  dim is that of sample_run()'s
 * runs (reads give the run's dim). */
mpm_energy_sample make_sample(int64_t run, int64_t i)
{
    mpm_energy_sample e;
    memset(&e, 0, sizeof e);
    double x = (double)i;
    e.seq = (uint64_t)i;
    e.step = 10 * i + 3;
    e.t = x * 1e-3 + 1.0 / 3.0;
    e.dim = 2;
    e.e.kinetic = sin(x) * 1e3 + (double)run;
    e.e.strain = cos(x) / 7.0;
    e.e.potential = -x * 9.81 / 3.0;
    e.e.external_work = i % 3 == 0 ? 1e-300 * x : DBL_MAX / (x + 1);
    e.e.total = e.e.kinetic + e.e.strain + e.e.potential - e.e.external_work;
    e.e.momentum[0] = 1.0 / (x + 1);
    e.e.momentum[1] = -exp(-x / 100);
    e.e.momentum[2] = i % 2 ? 5e-324 : -2.5;
    e.e.mass = 2.0 + x * 1e-9;
    e.e.angular_momentum[0] = 1.0 / (x + 3);
    e.e.angular_momentum[1] = -x * x * 1e200;
    e.e.angular_momentum[2] = i % 2 ? 5e-324 : 7.5 + x;
    return e;
}

/* 1 if sample es[i] equals make_sample(run, seq) bit for bit. */
int sample_equals(const mpm_energy_sample *es, size_t i, int64_t run, int64_t seq)
{
    mpm_energy_sample e = make_sample(run, seq);
    const mpm_energy_sample *g = &es[i];
    return g->seq == e.seq && g->step == e.step && g->t == e.t && g->dim == e.dim &&
           g->e.kinetic == e.e.kinetic && g->e.strain == e.e.strain &&
           g->e.potential == e.e.potential && g->e.external_work == e.e.external_work &&
           g->e.total == e.e.total && g->e.momentum[0] == e.e.momentum[0] &&
           g->e.momentum[1] == e.e.momentum[1] && g->e.momentum[2] == e.e.momentum[2] &&
           g->e.mass == e.e.mass && g->e.angular_momentum[0] == e.e.angular_momentum[0] &&
           g->e.angular_momentum[1] == e.e.angular_momentum[1] &&
           g->e.angular_momentum[2] == e.e.angular_momentum[2];
}
