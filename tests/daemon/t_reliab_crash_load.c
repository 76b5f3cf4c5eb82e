/*
 * t_reliab_crash_load.c - the reliability suite's crash and load parts (rel_*; quick
 * sizes in `make test`, full sizes with MPM_STRESS=full in `make stress`):
 *  - rel_kill9: a real mpmd killed with SIGKILL at random moments (seeded,
 *    the seed printed; MPM_REL_SEED repeats a sequence) while clients
 *    submit jobs that record energies and snapshots, restarted on the same
 *    database each time; after each restart the file passes PRAGMA
 *    integrity_check, every run is in a terminal state or INTERRUPTED, and
 *    its data is intact (the energy series decodes, is consecutive, its
 *    steps increase, its count is RunInfo's; every recorded snapshot
 *    decodes with the run's particle count);
 *  - rel_load: many clients at once, each its own thread and socket,
 *    submitting small jobs; every request is answered, QUEUE_FULL refusals
 *    are counted and retried, and every accepted job is recorded once.
 * Each prints one "reliability: ..." line for docs/reliability.md's table.
 */
#include "t_daemon.h"
#include "t_daemon_util.h"
#include "t_stress.h"

#include <pthread.h>
#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>
#include <unistd.h>

#include "mpp_case.h"
#include "store.h"

/* A case (consumed) as packed Case bytes (malloc'd); 0 or -1. */
static int pack_case(json_t *c, uint8_t **buf, size_t *len)
{
    char *text = c ? json_dumps(c, JSON_COMPACT) : NULL, err[ERRLEN];
    Mpmd__Case *pb = NULL;
    int rc = -1;
    json_decref(c);
    if (text && td_case_from_json(text, strlen(text), &pb, err, sizeof err) == 0)
        rc = mpp_case_pack(pb, buf, len) ? -1 : 0;
    else
        TLOG("pack_case: %s", text ? err : "no case");
    mpp_case_pb_free(&pb);
    free(text);
    return rc;
}

/* Submits packed case bytes as a raw request: the new job's id (> 0), 0
 * when refused (the code in code, n bytes), -1 without a reply. */
static long long submit_bytes(const char *ep, const uint8_t *cb, size_t cl, double timeout,
                              char *code, size_t n)
{
    mpp_request rq = {.kind = MPP_REQ_SUBMIT, .case_bytes = cb, .case_len = cl};
    json_t *reply = NULL;
    long long id = -1;
    if (code && n) code[0] = 0;
    if (td_request(ep, &rq, timeout, &reply) == 0) {
        json_t *ok = json_object_get(reply, "submitOk");
        id = ok ? jint(ok, "jobId") : 0;
        if (!ok && code) snprintf(code, n, "%s", td_err_code(reply));
    }
    json_decref(reply);
    return id;
}

/* The seed of the random moments: MPM_REL_SEED, else from the clock. */
static unsigned long rel_seed(void)
{
    const char *e = getenv("MPM_REL_SEED");
    return e && *e ? strtoul(e, NULL, 10) : (unsigned long)time(NULL) ^ (unsigned long)getpid();
}

static int cmp_ll(const void *a, const void *b)
{
    long long x = *(const long long *)a, y = *(const long long *)b;
    return (x > y) - (x < y);
}

/* ---- kill -9 ------------------------------------------------------------------------ */

typedef struct {
    long runs, interrupted, finished, other_end, samples, snapshots;
    long integrity_failures, bad_state, bad_data;
} kill_tally;

static int terminal(const char *st)
{
    return !strcmp(st, "FINISHED") || !strcmp(st, "FAILED") || !strcmp(st, "CANCELLED") ||
           !strcmp(st, "INTERRUPTED");
}

/* Checks one run's stored data (a restarted daemon answers): the energy
 * series, consecutive with increasing steps, as many samples as RunInfo
 * says and its last one at the run's step; the last two recorded
 * snapshots decode with the run's particles.  0, or -1 with the reason
 * printed. */
static int run_intact(const td_daemon *d, unsigned long long id, kill_tally *k)
{
    json_t *r = show_json(d, id);
    td_out o;
    series s = {0};
    int rc = -1;
    char ids[32];
    if (!r) return -1;
    snprintf(ids, sizeof ids, "%llu", id);
    long long nsamples = jint(r, "energySamples"), steps = jint(r, "steps");
    long long particles = jint(r, "particles"), dim = jint(r, "dim");
    const char *st = jstr(r, "status");
    if (nsamples < 0) nsamples = 0;
    if (td_ctl(d, 60, &o, "energy", ids, "--csv", NULL) || o.status) {
        TLOG("run %llu: energy --csv: exit %d %s", id, o.status, o.err ? o.err : "");
        goto out;
    }
    /* a run that never started has no series (and mpmctl prints none) */
    if ((o.out[0] || nsamples) && parse_csv(o.out, &s)) goto out;
    if ((long long)s.n != nsamples || !consecutive(&s)) {
        TLOG("run %llu (%s): %zu samples read, RunInfo says %lld", id, st, s.n, nsamples);
        goto out;
    }
    for (size_t i = 1; i < s.n; i++)
        if (s.step[i] <= s.step[i - 1]) {
            TLOG("run %llu: sample %zu at step %lld after step %lld", id, i, s.step[i],
                 s.step[i - 1]);
            goto out;
        }
    if (s.n && (!strcmp(st, "FINISHED") || !strcmp(st, "INTERRUPTED")) &&
        s.step[s.n - 1] != steps) {
        TLOG("run %llu (%s) at step %lld, its last sample at %lld", id, st, steps, s.step[s.n - 1]);
        goto out;
    }
    k->samples += (long)s.n;
    json_t *ss = json_object_get(r, "snapshotSteps");
    size_t ns = json_array_size(ss);
    for (size_t i = ns > 2 ? ns - 2 : 0; i < ns; i++) {
        json_t *v = json_array_get(ss, i), *reply = NULL;
        long long step = json_is_string(v) ? atoll(json_string_value(v)) : json_integer_value(v);
        mpp_request rq = {.kind = MPP_REQ_GET_SNAPSHOT, .id = id, .has_step = 1, .step = step};
        int got = td_request(d->ep, &rq, 60, &reply);
        json_t *sn = got == 0 ? json_object_get(reply, "snapshot") : NULL;
        long long n = sn ? jint(sn, "n") : -1;
        size_t nx = sn ? json_array_size(json_object_get(sn, "x")) : 0;
        int ok = sn && n == particles && jint(sn, "step") == step &&
                 (long long)nx == particles * (dim > 0 ? dim : 1);
        if (!ok)
            TLOG("run %llu: snapshot at step %lld: %s, n %lld, %zu positions (want %lld x %lld)",
                 id, step, sn ? "decoded" : td_err_code(reply), n, nx, particles, dim);
        json_decref(reply);
        if (!ok) goto out;
        k->snapshots++;
    }
    rc = 0;
out:
    series_free(&s);
    td_out_free(&o);
    json_decref(r);
    return rc;
}

/* After a restart: the integrity check, every run's state, and the data of
 * the runs above *checked (each run's data is checked once, after the
 * restart that follows its end); *checked moves up. */
static void check_after_restart(const td_daemon *d, unsigned long long *checked, kill_tally *k)
{
    int ok = 0;
    char rep[512];
    if (store_integrity_check(d->db, &ok, rep, sizeof rep) || !ok) {
        TLOG("integrity_check: %s", ok ? "" : rep[0] ? rep : store_error()->message);
        k->integrity_failures++;
    }
    td_out o;
    char **lines = NULL;
    if (td_ctl(d, 60, &o, "runs", "--all", "--json", NULL) || o.status) {
        TLOG("runs --all: exit %d %s", o.status, o.err ? o.err : "");
        k->bad_state++;
        td_out_free(&o);
        return;
    }
    size_t n = td_lines(o.out, &lines);
    unsigned long long top = *checked;
    for (size_t i = 0; i < n; i++) {
        json_t *r = parse_line(lines[i]);
        unsigned long long id = r ? (unsigned long long)jint(r, "runId") : 0;
        const char *st = r ? jstr(r, "status") : "";
        if (!terminal(st)) {
            TLOG("run %llu is %s after a restart", id, st);
            k->bad_state++;
        } else if (id > *checked) {
            k->runs++;
            k->interrupted += !strcmp(st, "INTERRUPTED");
            k->finished += !strcmp(st, "FINISHED");
            k->other_end += strcmp(st, "INTERRUPTED") && strcmp(st, "FINISHED");
            if (run_intact(d, id, k)) k->bad_data++;
        }
        if (id > top) top = id;
        json_decref(r);
    }
    *checked = top;
    free(lines);
    td_out_free(&o);
}

DTEST(rel_kill9)
{
    const char *tmp = t_tmpdir();
    const char *extra[] = {"--workers", "2", "--solver-threads", "1", NULL};
    const int full = t_stress_full(), kills = full ? 100 : 6;
    char dir[300], longp[400];
    td_daemon d;
    uint8_t *shortb = NULL, *longb = NULL;
    size_t shortl = 0, longl = 0;
    kill_tally k = {0};
    unsigned long long checked = 0;
    long accepted = 0, in_flight_ok = 0, nids = 0;
    /* every id a SubmitOk gave (mpmd replies only once the run's row is
     * committed): each must be found after the kills */
    long long *ids = calloc((size_t)kills * 4 + 1, sizeof *ids);
    CHECK(ids);
    unsigned long seed = rel_seed();
    srand48((long)seed);
    snprintf(dir, sizeof dir, "%s/kill9", tmp);
    if (td_start(&d, dir, extra)) return;

    /* a short job (300 steps: energy every step, a snapshot every 50,
     * recorded) and a long one (the bar at rest until killed: energy every
     * 50 steps, a recorded snapshot every 2000) */
    json_t *c = block2d(300, 1, "short");
    CHECK(c);
    set_output(c, "snapshotEvery", json_integer(50));
    set_output(c, "recordSnapshots", json_true());
    CHECK(pack_case(c, &shortb, &shortl) == 0);
    c = long_case(50);
    CHECK(c);
    set_output(c, "snapshotEvery", json_integer(2000));
    set_output(c, "recordSnapshots", json_true());
    json_incref(c);
    CHECK(write_case(c, dir, "long.json", longp, sizeof longp) == 0);
    CHECK(pack_case(c, &longb, &longl) == 0);

    TLOG("seed %lu (MPM_REL_SEED=%lu repeats it), %d kills", seed, seed, kills);
    double t0 = td_now(), delay_sum = 0;
    for (int round = 0; round < kills && !t_failed(); round++) {
        char code[64];
        /* the clients: a long job, two short ones, and mpmctl submitting
         * while the kill comes */
        long long id = submit_bytes(d.ep, longb, longl, 30, code, sizeof code);
        accepted += id > 0;
        if (id > 0) ids[nids++] = id;
        for (int j = 0; j < 2; j++) {
            long long s = submit_bytes(d.ep, shortb, shortl, 30, code, sizeof code);
            accepted += s > 0;
            if (s > 0) ids[nids++] = s;
            if (s < 0) t_fail(__FILE__, __LINE__, "kill %d: a submit got no reply", round);
        }
        td_bg bg;
        CHECK(td_ctl_bg(&d, &bg, "submit", "submit", longp, NULL) == 0);
        int ms = (int)(drand48() * (full ? 400 : 250));
        delay_sum += ms;
        td_msleep(ms);
        /* the daemon and its client die together: what the client sent
         * may or may not have been recorded */
        td_kill9(&d);
        kill(bg.pid, SIGKILL);
        td_out o = {0};
        CHECK(td_bg_wait(&bg, 60, &o) == 0);
        if (o.status == 0 && job_of(o.out) > 0) {
            in_flight_ok++;
            ids[nids++] = (long long)job_of(o.out);
        }
        td_out_free(&o);
        if (td_start(&d, dir, extra)) return;
        check_after_restart(&d, &checked, &k);
    }
    /* the end: every run once more, after a clean stop and start */
    CHECK(td_stop(&d) == 0);
    if (td_start(&d, dir, extra)) return;
    unsigned long long none = checked;
    kill_tally last = {0};
    check_after_restart(&d, &none, &last);
    k.integrity_failures += last.integrity_failures;
    k.bad_state += last.bad_state;
    /* nothing accepted is lost: every id a SubmitOk gave is listed */
    long lost = nids;
    {
        td_out o = {0};
        char **lines = NULL;
        long long *listed = NULL;
        size_t nl = 0, nlisted = 0;
        if (td_ctl(&d, 60, &o, "runs", "--all", "--json", NULL) == 0 && o.status == 0) {
            nl = td_lines(o.out, &lines);
            listed = calloc(nl + 1, sizeof *listed);
            for (size_t i = 0; listed && i < nl; i++) {
                json_t *r = parse_line(lines[i]);
                if (r) listed[nlisted++] = jint(r, "runId");
                json_decref(r);
            }
            free(lines);
            if (listed) {
                qsort(listed, nlisted, sizeof *listed, cmp_ll);
                lost = 0;
                for (long i = 0; i < nids; i++)
                    lost += !bsearch(&ids[i], listed, nlisted, sizeof *listed, cmp_ll);
            }
        }
        td_out_free(&o);
        free(listed);
    }
    free(ids);
    free(shortb);
    free(longb);
    CHECK(td_stop(&d) == 0); /* the last daemon too: none is left running */
    TLOG("%d kills in %.1f s (mean delay %.0f ms): %ld runs, %ld finished, %ld interrupted, "
         "%ld other ends; %ld energy samples and %ld snapshots verified; accepted %ld (+%ld "
         "mpmctl submits answered before the kill)",
         kills, td_now() - t0, delay_sum / kills, k.runs, k.finished, k.interrupted, k.other_end,
         k.samples, k.snapshots, accepted, in_flight_ok);
    printf(
        "reliability: kill9 kills=%d runs=%ld interrupted=%ld finished=%ld integrity_failures=%ld "
        "bad_state=%ld bad_data=%ld accepted=%ld accepted_lost=%ld seed=%lu\n",
        kills, k.runs, k.interrupted, k.finished, k.integrity_failures, k.bad_state, k.bad_data,
        nids, lost, seed);
    CHECKF(lost == 0, "%ld of the %ld jobs a SubmitOk accepted are not recorded", lost, nids);
    CHECKF(k.integrity_failures == 0 && k.bad_state == 0 && k.bad_data == 0,
           "integrity failures %ld, runs not ended %ld, runs with damaged data %ld",
           k.integrity_failures, k.bad_state, k.bad_data);
    CHECK(k.runs >= kills && k.interrupted > 0);
}

/* ---- load ----------------------------------------------------------------------------- */

typedef struct {
    const char *ep;
    const uint8_t *cb;
    size_t cl;
    int jobs;
    long long *ids;    /* jobs accepted, in order */
    int accepted;      /* how many */
    long refused_full; /* QUEUE_FULL answers, each retried */
    long other_errors; /* any other refusal */
    long unanswered;   /* requests without a reply in the timeout */
    unsigned seed;
} load_client;

static void *load_run(void *arg)
{
    load_client *lc = arg;
    for (int j = 0; j < lc->jobs;) {
        char code[64];
        long long id = submit_bytes(lc->ep, lc->cb, lc->cl, 60, code, sizeof code);
        if (id > 0) {
            lc->ids[lc->accepted++] = id;
            j++;
        } else if (id < 0) {
            lc->unanswered++;
            j++; /* not retried: it may have been accepted */
        } else if (!strcmp(code, "QUEUE_FULL")) {
            lc->refused_full++;
            td_msleep(5 + (int)(rand_r(&lc->seed) % 20));
        } else {
            lc->other_errors++;
            j++;
        }
    }
    return NULL;
}

DTEST(rel_load)
{
    const char *tmp = t_tmpdir();
    /* a short queue, so that clients meet QUEUE_FULL and retry */
    const char *extra[] = {"--workers", "2", "--queue-max", "4", "--solver-threads", "1", NULL};
    const int full = t_stress_full(), nc = full ? 50 : 8, nj = full ? 20 : 5;
    char dir[300], st[32];
    td_daemon d;
    uint8_t *cb = NULL;
    size_t cl = 0;
    snprintf(dir, sizeof dir, "%s/load", tmp);
    if (td_start(&d, dir, extra)) return;
    CHECK(pack_case(bar_steps(20, 5), &cb, &cl) == 0);

    load_client *lc = calloc((size_t)nc, sizeof *lc);
    pthread_t *th = calloc((size_t)nc, sizeof *th);
    long long *all = calloc((size_t)nc * (size_t)nj, sizeof *all);
    CHECK(lc && th && all);
    int started = 0;
    double t0 = td_now();
    for (int i = 0; i < nc; i++) {
        lc[i] = (load_client){.ep = d.ep,
                              .cb = cb,
                              .cl = cl,
                              .jobs = nj,
                              .ids = all + i * nj,
                              .seed = (unsigned)i + 1};
        if (pthread_create(&th[i], NULL, load_run, &lc[i])) break;
        started++;
    }
    for (int i = 0; i < started; i++) pthread_join(th[i], NULL);
    double secs = td_now() - t0;
    long accepted = 0, full_refusals = 0, other = 0, unanswered = 0;
    int n = 0;
    for (int i = 0; i < started; i++) {
        for (int j = 0; j < lc[i].accepted; j++) all[n++] = lc[i].ids[j];
        accepted += lc[i].accepted;
        full_refusals += lc[i].refused_full;
        other += lc[i].other_errors;
        unanswered += lc[i].unanswered;
    }
    free(lc);
    free(th);
    free(cb);
    /* ids unique */
    qsort(all, (size_t)n, sizeof *all, cmp_ll);
    long dups = 0;
    for (int i = 1; i < n; i++) dups += all[i] == all[i - 1];
    long long maxid = n ? all[n - 1] : 0;
    int done =
        n && td_wait_status(&d, (unsigned long long)maxid, "FINISHED|FAILED|CANCELLED|INTERRUPTED",
                            300, st, sizeof st) == 0;
    /* recorded once each: the listing holds exactly the accepted ids */
    td_out o;
    char **lines = NULL;
    long listed = 0, unknown = 0, not_finished = 0;
    if (td_ctl(&d, 60, &o, "runs", "--all", "--json", NULL) == 0 && o.status == 0) {
        size_t nl = td_lines(o.out, &lines);
        for (size_t i = 0; i < nl; i++) {
            json_t *r = parse_line(lines[i]);
            long long id = r ? jint(r, "runId") : -1;
            listed++;
            unknown += !bsearch(&id, all, (size_t)n, sizeof *all, cmp_ll);
            not_finished += r && strcmp(jstr(r, "status"), "FINISHED") != 0;
            json_decref(r);
        }
        free(lines);
    }
    td_out_free(&o);
    free(all);
    TLOG("%d clients x %d jobs in %.1f s: %ld accepted, %ld QUEUE_FULL refusals retried, %ld "
         "other refusals, %ld unanswered; %ld runs listed (%ld not accepted, %ld duplicate ids, "
         "%ld not FINISHED)",
         started, nj, secs, accepted, full_refusals, other, unanswered, listed, unknown, dups,
         not_finished);
    printf("reliability: load clients=%d jobs=%d accepted=%ld queue_full_retried=%ld "
           "unanswered=%ld recorded=%ld duplicates=%ld secs=%.1f\n",
           started, nj, accepted, full_refusals, unanswered, listed, dups, secs);
    CHECK(started == nc && done);
    CHECKF(unanswered == 0 && other == 0 && accepted == (long)nc * nj,
           "unanswered %ld, other refusals %ld, accepted %ld of %d", unanswered, other, accepted,
           nc * nj);
    CHECKF(listed == accepted && unknown == 0 && dups == 0 && not_finished == 0,
           "listed %ld of %ld accepted, %ld unknown, %ld duplicates, %ld not FINISHED", listed,
           accepted, unknown, dups, not_finished);
}
