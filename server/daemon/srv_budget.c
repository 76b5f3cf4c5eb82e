/*
 * srv_budget.c - the disk budgets (see srv_budget.h): the recorded bytes
 * of each owner and of the whole database, kept in memory from one store
 * query at start, the estimate of a case's recorded bytes, the check at
 * submit and the charge of each write while a job runs.
 */
#include "srv_budget.h"

#include "srv_grow.h"

#include <math.h>
#include <pthread.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#define MIB 1048576.0

typedef struct {
    char owner[48];
    int64_t bytes;
    long long quota_mb; /* the client's disk quota (0: none) */
} owner_total;

struct srv_budget {
    const srv_config *cfg;
    pthread_mutex_t mu;
    int64_t total;    /* every owner's */
    owner_total *tab; /* per owner (linear: the owners are the listed keys) */
    size_t n, cap;
};

static owner_total *find_locked(srv_budget *b, const char *owner, int add)
{
    for (size_t i = 0; i < b->n; i++)
        if (!strncmp(b->tab[i].owner, owner, sizeof b->tab[i].owner - 1)) return &b->tab[i];
    if (!add) return NULL;
    owner_total *t = srv_grow(b->tab, &b->cap, b->n + 1, sizeof *t, 0);
    if (!t) return NULL;
    b->tab = t;
    owner_total *o = &b->tab[b->n++];
    snprintf(o->owner, sizeof o->owner, "%s", owner);
    o->bytes = 0;
    o->quota_mb = b->cfg->client_max_disk_mb;
    return o;
}

srv_budget *srv_budget_new(const srv_config *cfg, store *st, char *err, size_t errlen)
{
    srv_budget *b = calloc(1, sizeof *b);
    if (!b) {
        snprintf(err, errlen, "out of memory");
        return NULL;
    }
    b->cfg = cfg;
    if (pthread_mutex_init(&b->mu, NULL)) {
        free(b);
        snprintf(err, errlen, "cannot create a mutex");
        return NULL;
    }
    store_owner_total *rows = NULL;
    size_t n = 0;
    if (store_owner_totals(st, &rows, &n)) {
        snprintf(err, errlen, "reading the recorded bytes of the runs: %s", store_error()->message);
        srv_budget_destroy(&b);
        return NULL;
    }
    /* one row per owner (GROUP BY): the table as read */
    b->tab = calloc(n ? n : 1, sizeof *b->tab);
    if (!b->tab) {
        snprintf(err, errlen, "out of memory");
        store_owner_totals_free(rows, n);
        srv_budget_destroy(&b);
        return NULL;
    }
    b->cap = n ? n : 1;
    for (size_t i = 0; i < n; i++) {
        owner_total *o = &b->tab[b->n++];
        snprintf(o->owner, sizeof o->owner, "%s", rows[i].owner ? rows[i].owner : "");
        o->bytes = rows[i].bytes;
        o->quota_mb = cfg->client_max_disk_mb;
        b->total += rows[i].bytes;
    }
    store_owner_totals_free(rows, n);
    return b;
}

void srv_budget_destroy(srv_budget **pb)
{
    srv_budget *b = pb ? *pb : NULL;
    if (!b) return;
    pthread_mutex_destroy(&b->mu);
    free(b->tab);
    free(b);
    *pb = NULL;
}

void srv_budget_estimate(const mpp_case *sc, double steps, srv_disk_estimate *out)
{
    memset(out, 0, sizeof *out);
    double n = (double)sc->info.particles, dim = sc->c.grid.dim;
    unsigned f = sc->snapshot_fields;
    /* the fields the run will have (as srv_job.c's snapshot() keeps) */
    if (!mpm_case_has_field(&sc->c, MPM_FIELD_PLASTIC_STRAIN))
        f &= ~(unsigned)MPP_SNAP_PLASTIC_STRAIN;
    if (!mpm_case_has_field(&sc->c, MPM_FIELD_DEFORMATION_GRADIENT))
        f &= ~(unsigned)MPP_SNAP_DEFORMATION_GRADIENT;
    if (!mpm_case_has_field(&sc->c, MPM_FIELD_YIELDED)) f &= ~(unsigned)MPP_SNAP_YIELDED;
    double per = 0;
    if (f & MPP_SNAP_X) per += dim;
    if (f & MPP_SNAP_V) per += dim;
    if (f & MPP_SNAP_STRESS) per += 6;
    if (f & MPP_SNAP_PRESSURE) per += 1;
    if (f & MPP_SNAP_VOLUME) per += 1;
    if (f & MPP_SNAP_PLASTIC_STRAIN) per += 1;
    if (f & MPP_SNAP_DEFORMATION_GRADIENT) per += dim * dim;
    if (f & MPP_SNAP_YIELDED) per += 1;
    /* one every snapshot_every steps, the initial state's and the end's */
    if (sc->record_snapshots && sc->snapshot_every)
        out->snapshots = 1 + ceil(steps / sc->snapshot_every);
    out->snapshot_bytes = n * per * (double)sizeof(double);
    /* the first sample, one every energy_every steps, the last */
    out->samples = 2 + (sc->energy_every ? floor(steps / sc->energy_every) : 0);
    out->bytes = out->snapshots * out->snapshot_bytes + out->samples * STORE_ENERGY_ROW_BYTES;
}

int srv_budget_admit(srv_budget *b, const char *owner, long long quota_mb,
                     const srv_disk_estimate *e, int automatic, mpm_error *err)
{
    const srv_config *cfg = b->cfg;
    double snap = e->snapshots * e->snapshot_bytes;
    const char *field = snap > 0 && snap >= e->samples * STORE_ENERGY_ROW_BYTES
                            ? "output.snapshot_every"
                            : "output.energy_every";
    char what[256];
    snprintf(what, sizeof what,
             "the run would record %s%.2f MiB (%.15g snapshots of %.15g bytes, %.15g energy "
             "samples of %d bytes)",
             automatic ? "at least " : "", e->bytes / MIB, e->snapshots, e->snapshot_bytes,
             e->samples, STORE_ENERGY_ROW_BYTES);
    if (cfg->job_max_disk_mb > 0 && e->bytes > (double)cfg->job_max_disk_mb * MIB)
        return mpm_fail(err, MPM_ETOOBIG, field,
                        "%s, above this server's per-job disk budget of %lld MiB "
                        "(--job-max-disk-mb)",
                        what, cfg->job_max_disk_mb);
    pthread_mutex_lock(&b->mu);
    int64_t total = b->total;
    owner_total *o = find_locked(b, owner, 1);
    int64_t mine = o ? o->bytes : 0;
    if (o) o->quota_mb = quota_mb;
    pthread_mutex_unlock(&b->mu);
    if (cfg->max_disk_mb > 0 && (double)total + e->bytes > (double)cfg->max_disk_mb * MIB)
        return mpm_fail(err, MPM_ETOOBIG, field,
                        "%s; the runs recorded take %.2f MiB, and with it they would pass this "
                        "server's disk budget of %lld MiB (--max-disk-mb)",
                        what, (double)total / MIB, cfg->max_disk_mb);
    if (quota_mb > 0 && (double)mine + e->bytes > (double)quota_mb * MIB)
        return mpm_fail(err, MPM_ETOOBIG, field,
                        "%s; %s's recorded runs take %.2f MiB, and with it they would pass this "
                        "server's per-client quota of %lld MiB (%s)",
                        what, owner, (double)mine / MIB, quota_mb,
                        quota_mb == cfg->client_max_disk_mb ? "--client-max-disk-mb"
                                                            : "max-disk-mb of its key");
    return 0;
}

int srv_budget_charge(srv_budget *b, const char *owner, int64_t *job_bytes, int64_t n, char *why,
                      size_t whylen)
{
    const srv_config *cfg = b->cfg;
    if (cfg->job_max_disk_mb > 0 && *job_bytes + n > cfg->job_max_disk_mb * 1048576LL) {
        snprintf(why, whylen,
                 "per-job disk budget reached: the run has recorded %.2f MiB and its next "
                 "%lld bytes would pass this server's budget of %lld MiB (--job-max-disk-mb)",
                 (double)*job_bytes / MIB, (long long)n, cfg->job_max_disk_mb);
        return MPM_ETOOBIG;
    }
    int rc = 0;
    pthread_mutex_lock(&b->mu);
    owner_total *o = find_locked(b, owner, 1);
    if (cfg->max_disk_mb > 0 && b->total + n > cfg->max_disk_mb * 1048576LL) {
        snprintf(why, whylen,
                 "disk budget reached: the runs recorded take %.2f MiB and this run's next "
                 "%lld bytes would pass this server's budget of %lld MiB (--max-disk-mb); "
                 "this run had recorded %.2f MiB",
                 (double)b->total / MIB, (long long)n, cfg->max_disk_mb, (double)*job_bytes / MIB);
        rc = MPM_ETOOBIG;
    } else if (o && o->quota_mb > 0 && o->bytes + n > o->quota_mb * 1048576LL) {
        snprintf(why, whylen,
                 "per-client disk quota reached: %s's runs take %.2f MiB and this run's next "
                 "%lld bytes would pass this server's quota of %lld MiB (%s); this run had "
                 "recorded %.2f MiB",
                 owner, (double)o->bytes / MIB, (long long)n, o->quota_mb,
                 o->quota_mb == cfg->client_max_disk_mb ? "--client-max-disk-mb"
                                                        : "max-disk-mb of its key",
                 (double)*job_bytes / MIB);
        rc = MPM_ETOOBIG;
    } else if (!o) {
        snprintf(why, whylen, "out of memory counting the recorded bytes");
        rc = MPM_ENOMEM;
    } else {
        o->bytes += n;
        b->total += n;
        *job_bytes += n;
    }
    pthread_mutex_unlock(&b->mu);
    return rc;
}

void srv_budget_refund(srv_budget *b, const char *owner, int64_t *job_bytes, int64_t n)
{
    pthread_mutex_lock(&b->mu);
    owner_total *o = find_locked(b, owner, 0);
    if (o) o->bytes -= n;
    b->total -= n;
    *job_bytes -= n;
    pthread_mutex_unlock(&b->mu);
}

int64_t srv_budget_owner(srv_budget *b, const char *owner)
{
    pthread_mutex_lock(&b->mu);
    owner_total *o = find_locked(b, owner, 0);
    int64_t v = o ? o->bytes : 0;
    pthread_mutex_unlock(&b->mu);
    return v;
}

int64_t srv_budget_total(srv_budget *b)
{
    pthread_mutex_lock(&b->mu);
    int64_t v = b->total;
    pthread_mutex_unlock(&b->mu);
    return v;
}
