/*
 * fuzz_seed.c - writes the seeds of the fuzz corpora (`make fuzz-seed`):
 * for each example case given (proto/examples/NAME.json) its JSON text
 * (json/), its packed Case (case/) and a Submit request carrying it
 * (request/); a request of every other kind (request/); and a stream
 * message and a reply of every kind (stream/).  The seeds are then merged
 * (libFuzzer -merge=1) into tests/fuzz/corpus/<target>/, which is kept in
 * the repository; this tool is built with the release libraries and run
 * only to renew them.
 *   fuzz_seed OUTDIR EXAMPLE.json...
 */
#include <errno.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>

#include "mpp_case.h"
#include "mpp_msg.h"

static const char *outdir;
static int failed;

/* Writes buf to OUTDIR/sub/name; counts a failure. */
static void put(const char *sub, const char *name, const void *buf, size_t len)
{
    char path[1024];
    snprintf(path, sizeof path, "%s/%s", outdir, sub);
    if (mkdir(path, 0755) && errno != EEXIST) {
        perror(path);
        failed++;
        return;
    }
    snprintf(path, sizeof path, "%s/%s/%s", outdir, sub, name);
    FILE *f = fopen(path, "wb");
    if (!f || fwrite(buf, 1, len, f) != len || fclose(f)) {
        perror(path);
        failed++;
    }
}

/* Stores an encoder's result (rc, *buf, *len: pointers, as the encoder
 * fills them while the arguments are evaluated) under sub/name and frees
 * it (*buf NULL again). */
static void put_enc(int rc, const char *sub, const char *name, uint8_t **buf, size_t *len)
{
    if (rc) {
        fprintf(stderr, "fuzz_seed: encoding %s/%s failed (%d)\n", sub, name, rc);
        failed++;
    } else
        put(sub, name, *buf, *len);
    free(*buf);
    *buf = NULL;
}

static char *slurp(const char *path, size_t *len)
{
    FILE *f = fopen(path, "rb");
    char *buf = NULL;
    long n;
    if (!f) return NULL;
    if (fseek(f, 0, SEEK_END) == 0 && (n = ftell(f)) >= 0 && fseek(f, 0, SEEK_SET) == 0 &&
        (buf = malloc((size_t)n + 1)) && fread(buf, 1, (size_t)n, f) == (size_t)n) {
        buf[n] = 0;
        *len = (size_t)n;
    } else {
        free(buf);
        buf = NULL;
    }
    fclose(f);
    return buf;
}

static void one_case(const char *path)
{
    char name[256];
    const char *base = strrchr(path, '/');
    base = base ? base + 1 : path;
    snprintf(name, sizeof name, "%.*s", (int)strcspn(base, "."), base);
    size_t len = 0;
    char *json = slurp(path, &len);
    Mpmd__Case *pb = NULL;
    mpm_error err;
    char file[300];
    if (!json || mpp_case_from_json(json, len, &pb, &err)) {
        fprintf(stderr, "fuzz_seed: %s: %s\n", path, json ? err.message : "unreadable");
        failed++;
        free(json);
        return;
    }
    snprintf(file, sizeof file, "%s.json", name);
    put("json", file, json, len);
    free(json);
    uint8_t *buf = NULL;
    size_t n = 0;
    snprintf(file, sizeof file, "%s.pb", name);
    put_enc(mpp_case_pack(pb, &buf, &n), "case", file, &buf, &n);
    mpp_request rq = {.kind = MPP_REQ_SUBMIT, .case_pb = pb};
    buf = NULL;
    snprintf(file, sizeof file, "submit_%s.bin", name);
    put_enc(mpp_request_encode(&rq, &buf, &n), "request", file, &buf, &n);
    mpp_case_pb_free(&pb);
}

static void requests(void)
{
    static const struct {
        const char *name;
        mpp_request rq;
    } k[] = {
        {"cancel", {.kind = MPP_REQ_CANCEL, .id = 3}},
        {"status", {.kind = MPP_REQ_STATUS, .id = 1}},
        {"list", {.kind = MPP_REQ_LIST_RUNS}},
        {"list_paged", {.kind = MPP_REQ_LIST_RUNS, .status = 3, .limit = 10, .before_id = 7}},
        {"get_run", {.kind = MPP_REQ_GET_RUN, .id = 2, .with_case = 1}},
        {"get_energy", {.kind = MPP_REQ_GET_ENERGY, .id = 2, .from_seq = 5, .limit = 100}},
        {"get_snapshot", {.kind = MPP_REQ_GET_SNAPSHOT, .id = 2, .has_step = 1, .step = 40}},
        {"get_snapshot_latest", {.kind = MPP_REQ_GET_SNAPSHOT, .id = 2}},
        {"ping", {.kind = MPP_REQ_PING}},
        {"version", {.kind = MPP_REQ_VERSION}},
        {"old_schema", {.kind = MPP_REQ_PING, .schema_version = 1}},
    };
    for (size_t i = 0; i < sizeof k / sizeof k[0]; i++) {
        uint8_t *buf = NULL;
        size_t n = 0;
        char file[64];
        snprintf(file, sizeof file, "%s.bin", k[i].name);
        put_enc(mpp_request_encode(&k[i].rq, &buf, &n), "request", file, &buf, &n);
    }
}

static void streams_and_replies(void)
{
    mpm_energy_sample es = {.seq = 4, .step = 40, .t = 0.25, .dim = 2};
    es.e.kinetic = 1.5;
    es.e.total = 2.5;
    double x[6] = {0.1, 0.2, 0.3, 0.4, 0.5, 0.6}, p[3] = {1, 2, 3};
    double st[18] = {0};
    int y[3] = {0, 1, 0};
    mpp_snapshot sn = {.step = 40,
                       .t = 0.25,
                       .n = 3,
                       .dim = 2,
                       .x = x,
                       .v = x,
                       .stress = st,
                       .pressure = p,
                       .volume = p,
                       .plastic_strain = p,
                       .yielded = y};
    mpp_progress pr = {.step = 40, .steps_total = 100, .t = 0.25, .dt = 1e-3, .wall_s = 0.5};
    mpp_finished fi = {.status = MPP_STATUS_FAILED,
                       .error = "a particle left the grid",
                       .steps = 40,
                       .t = 0.25,
                       .wall_s = 0.5,
                       .energy = &es,
                       .has_balance = 1,
                       .balance_error = 1e-6,
                       .warning = "w"};
    int64_t steps[2] = {10, 20};
    mpp_run_info ri = {.run_id = 2,
                       .job_id = 2,
                       .name = "disk",
                       .status = MPP_STATUS_FINISHED,
                       .error = "",
                       .submitted_at = 1e9,
                       .started_at = 1e9 + 1,
                       .finished_at = 1e9 + 2,
                       .steps = 40,
                       .steps_total = 40,
                       .t = 0.25,
                       .wall_s = 1,
                       .particles = 3,
                       .nodes = 9,
                       .dim = 2,
                       .last_energy = &es,
                       .energy_samples = 5,
                       .n_snapshot_steps = 2,
                       .snapshot_steps = steps,
                       .owner = "local"};
    const char *names[] = {"libzmq", "sqlite"}, *vers[] = {"4.3.4", "3.40.1"};
    uint8_t *b = NULL;
    size_t n = 0;
    put_enc(mpp_stream_progress(2, 1, &pr, &b, &n), "stream", "progress.bin", &b, &n);
    put_enc(mpp_stream_energy(2, 2, &es, &b, &n), "stream", "energy.bin", &b, &n);
    put_enc(mpp_stream_snapshot(2, 3, &sn, &b, &n), "stream", "snapshot.bin", &b, &n);
    put_enc(mpp_stream_finished(2, 4, &fi, &b, &n), "stream", "finished.bin", &b, &n);
    put_enc(mpp_reply_error(3, "bodies[0]: bad", "bodies[0]", &b, &n), "stream", "r_error.bin", &b,
            &n);
    put_enc(mpp_reply_submit_ok(2, 2, &b, &n), "stream", "r_submit_ok.bin", &b, &n);
    put_enc(mpp_reply_run(&ri, &b, &n), "stream", "r_run.bin", &b, &n);
    mpp_run_info two[2] = {ri, ri};
    put_enc(mpp_reply_runs_page(two, 2, 1, &b, &n), "stream", "r_runs.bin", &b, &n);
    put_enc(mpp_reply_energy(2, &es, 1, 1, &b, &n), "stream", "r_energy.bin", &b, &n);
    put_enc(mpp_reply_snapshot(&sn, &b, &n), "stream", "r_snapshot.bin", &b, &n);
    put_enc(mpp_reply_pong("1.0", "ipc:///tmp/x.stream", &b, &n), "stream", "r_pong.bin", &b, &n);
    put_enc(mpp_reply_version("1.0", names, vers, 2, &b, &n), "stream", "r_version.bin", &b, &n);
}

int main(int argc, char **argv)
{
    if (argc < 2) {
        fprintf(stderr, "usage: fuzz_seed OUTDIR EXAMPLE.json...\n");
        return 2;
    }
    outdir = argv[1];
    if (mkdir(outdir, 0755) && errno != EEXIST) {
        perror(outdir);
        return 1;
    }
    for (int i = 2; i < argc; i++) one_case(argv[i]);
    requests();
    streams_and_replies();
    return failed ? 1 : 0;
}
