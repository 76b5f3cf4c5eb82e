/*
 * t_daemon_input.c - a real mpmd against bad input: every bad case, bad
 * request and bad frame sequence gets its error with the field and the
 * limit, and the daemon keeps answering.
 */
#include "t_daemon.h"
#include "t_daemon_util.h"

#include <stdlib.h>
#include <string.h>
#include <zmq.h>

#include "mpm.h"

/* ---- bad input ----------------------------------------------------------------------- */

/* Sends Submit(case) raw and checks code and field (field exact, or a
 * prefix when it ends with '*'); the message must start with the field. */
static int submit_expect(const td_daemon *d, Mpmd__Case *pb, const char *what, const char *code,
                         const char *field)
{
    mpp_request rq = {.kind = MPP_REQ_SUBMIT, .case_pb = pb};
    json_t *reply = NULL;
    int ok = 0;
    size_t fl = strlen(field);
    int prefix = fl && field[fl - 1] == '*';
    if (td_request(d->ep, &rq, 20, &reply) != 0) {
        t_fail(__FILE__, __LINE__, "%s: no reply", what);
    } else {
        const char *f = td_err_field(reply), *m = td_err_msg(reply);
        size_t n = prefix ? fl - 1 : fl;
        ok = !strcmp(td_err_code(reply), code) && !strncmp(f, field, n) && (prefix || !f[n]) &&
             !strncmp(m, f, strlen(f)) && m[strlen(f)] == ':';
        if (!ok)
            t_fail(__FILE__, __LINE__,
                   "%s: got %s, field \"%s\", message \"%s\" (want %s, field %s)", what,
                   td_err_code(reply), f, m, code, field);
        else
            TLOG("%-28.28s %s %s", what, td_err_code(reply), m);
    }
    json_decref(reply);
    return ok;
}

/* The good case patched, checked through the daemon only. */
static int bad_case(const td_daemon *d, const char *from, const char *to, const char *code,
                    const char *field)
{
    char err[ERRLEN], what[64];
    char *json = td_patch(from, to);
    Mpmd__Case *pb = NULL;
    int ok;
    if (!json || td_case_from_json(json, strlen(json), &pb, err, sizeof err)) {
        t_fail(__FILE__, __LINE__, "patch %s -> %s: %s", from, to, json ? err : "not in the case");
        free(json);
        return 0;
    }
    snprintf(what, sizeof what, "%s", to);
    ok = submit_expect(d, pb, what, code, field);
    mpp_case_pb_free(&pb);
    free(json);
    return ok;
}

/* Expects a raw message to get `code` (or, if may_drop, no reply). */
static int frames_expect(const td_daemon *d, const char *what, const void *const *f,
                         const size_t *l, int n, const char *code, int may_drop)
{
    json_t *reply = NULL;
    int rc = td_frames(d->ep, f, l, n, may_drop ? 1.5 : 10, &reply), ok;
    ok = rc == 0 ? !strcmp(td_err_code(reply), code) : (rc == 1 && may_drop);
    if (!ok)
        t_fail(__FILE__, __LINE__, "%s: %s%s (want %s%s)", what,
               rc == 0 ? "error code " : "no reply", rc == 0 ? td_err_code(reply) : "", code,
               may_drop ? " or no reply" : "");
    else
        TLOG("%-28.28s %s %s", what, rc == 0 ? td_err_code(reply) : "dropped (no reply)",
             rc == 0 ? td_err_msg(reply) : "");
    json_decref(reply);
    return ok;
}

DTEST(daemon_bad_input)
{
    const char *tmp = t_tmpdir();
    const char *extra[] = {"--max-request-bytes", "100000", "--max-particles", "5000", NULL};
    char dir[300], path[400], err[ERRLEN];
    td_daemon d;
    td_out o;

    snprintf(dir, sizeof dir, "%s/d", tmp);
    if (td_start(&d, dir, extra)) return;

    /* cases the schema accepts but the checks refuse, each naming its field */
    CHECK(bad_case(&d, "\"youngsModulus\": 1", "\"youngsModulus\": -1", "INVALID_CASE",
                   "materials[0].youngsModulus"));
    CHECK(bad_case(&d, "\"youngsModulus\": 1", "\"youngsModulus\": 0", "INVALID_CASE",
                   "materials[0].youngsModulus"));
    CHECK(bad_case(&d, "\"density\": 1", "\"density\": 0", "INVALID_CASE", "materials[0].density"));
    CHECK(bad_case(&d, "\"spacing\": [0.1, 0.1]", "\"spacing\": [0.1, -0.1]", "INVALID_CASE",
                   "grid.spacing[1]"));
    CHECK(bad_case(&d, "\"poissonRatio\": 0.2", "\"poissonRatio\": 0.5", "INVALID_CASE",
                   "materials[0].poissonRatio"));
    CHECK(bad_case(&d, "\"poissonRatio\": 0.2", "\"poissonRatio\": -1.5", "INVALID_CASE",
                   "materials[0].poissonRatio"));
    CHECK(bad_case(&d, "\"center\": [0.3, 0.3]", "\"center\": [3.3, 0.3]", "INVALID_CASE",
                   "bodies[0]*"));
    CHECK(bad_case(&d, "\"radius\": 0.1", "\"radius\": 0.001", "INVALID_CASE", "bodies[0]*"));
    CHECK(bad_case(&d, "\"endTime\": 1", "\"endTime\": 1, \"dt\": 0.5", "INVALID_CASE", "dt"));
    CHECK(bad_case(&d, "\"endTime\": 1", "\"endTime\": 0", "INVALID_CASE", "endTime"));
    CHECK(bad_case(&d, ", \"endTime\": 1", "", "INVALID_CASE", "endTime"));
    CHECK(bad_case(&d, "\"velocity\": [-0.1, 0]", "\"velocity\": [-0.1, 0], \"ppc\": 9",
                   "INVALID_CASE", "bodies[1].ppc"));
    CHECK(bad_case(&d, "\"spacing\": [0.1, 0.1]", "\"spacing\": [0.1, 0.1, 0.1]", "INVALID_CASE",
                   "grid.spacing"));
    CHECK(bad_case(&d, "\"dim\": 2", "\"dim\": 4", "INVALID_CASE", "grid.dim"));
    /* the verification policy (mpm_verified.c): refused at submit */
    CHECK(bad_case(&d, "\"endTime\": 1", "\"endTime\": 1, \"method\": \"MPM\", \"update\": \"USL\"",
                   "INVALID_CASE", "update"));
    CHECK(bad_case(&d, "\"endTime\": 1",
                   "\"endTime\": 1, \"method\": \"BSPLINE3\", \"boundary\": {\"friction\": "
                   "[{\"face\": \"Y_LO\", \"mu\": 0.2}]}",
                   "INVALID_CASE", "method"));
    /* too many steps: endTime / dt far beyond any integer is refused, not
     * wrapped into a negative count that passes the limit */
    CHECK(bad_case(&d, "\"endTime\": 1", "\"endTime\": 1e300, \"dt\": 0.001", "TOO_LARGE",
                   "endTime"));
    CHECK(
        bad_case(&d, "\"endTime\": 1", "\"endTime\": 1e6, \"dt\": 0.001", "TOO_LARGE", "endTime"));
    CHECK(bad_case(&d, "\"endTime\": 1", "\"steps\": 200000000", "TOO_LARGE", "steps"));
    /* too large: the codec's node limit, and this server's --max-particles */
    CHECK(
        bad_case(&d, "\"nodes\": [11, 11]", "\"nodes\": [5001, 5001]", "TOO_LARGE", "grid.nodes"));
    {
        /* 6000 explicit points in 1D: 96 KB, under the request limit, over --max-particles */
        json_t *c =
            json_pack("{s:{s:i,s:[f],s:[i]},s:[{s:f,s:f}],s:[{s:{s:[],s:[]}}],s:i}", "grid", "dim",
                      1, "spacing", 0.001, "nodes", 7001, "materials", "youngsModulus", 1.0,
                      "density", 1.0, "bodies", "points", "x", "volume", "steps", 10);
        json_t *pts = json_object_get(json_array_get(json_object_get(c, "bodies"), 0), "points");
        char *text;
        Mpmd__Case *pb = NULL;
        for (int i = 0; i < 6000; i++) {
            json_array_append_new(json_object_get(pts, "x"), json_real(0.0005 + 0.001 * i));
            json_array_append_new(json_object_get(pts, "volume"), json_real(0.001));
        }
        text = json_dumps(c, 0);
        json_decref(c);
        CHECK(text && td_case_from_json(text, strlen(text), &pb, err, sizeof err) == 0);
        free(text);
        int ok = submit_expect(&d, pb, "6000 points > --max-particles", "TOO_LARGE", "bodies*");
        mpp_case_pb_free(&pb);
        CHECK(ok);
    }
    {
        /* an enum value the schema does not know: only possible as bytes
         * (the JSON reader refuses it); Case.method = field 3, varint 7 */
        char *json = td_patch("\"endTime\": 1", "\"endTime\": 1");
        Mpmd__Case *pb = NULL, *bad = NULL;
        uint8_t *buf = NULL, *b2;
        size_t len = 0;
        int ok;
        CHECK(json && td_case_from_json(json, strlen(json), &pb, err, sizeof err) == 0);
        free(json);
        CHECK(mpp_case_pack(pb, &buf, &len) == 0);
        mpp_case_pb_free(&pb);
        b2 = realloc(buf, len + 2);
        CHECK(b2);
        b2[len] = 0x18;
        b2[len + 1] = 0x07;
        CHECKF(td_case_unpack(b2, len + 2, 0, &bad, err, sizeof err) == 0, "%s", err);
        free(b2);
        ok = submit_expect(&d, bad, "method = 7 (unknown enum)", "INVALID_CASE", "method");
        mpp_case_pb_free(&bad);
        CHECK(ok);
    }

    /* the client checks locally first, the server's limits come back with the field */
    CHECK(td_write((snprintf(path, sizeof path, "%s/bad.json", dir), path),
                   "{\"grid\": {\"dim\": 1, \"spacing\": [0.1], \"nodes\": [11]},"
                   " \"materials\": [{\"youngsModulus\": 1, \"density\": -2}],"
                   " \"bodies\": [{\"box\": {\"lo\": [0.2], \"hi\": [0.4]}}], \"endTime\": 1}") ==
          0);
    EXPECT_CTL(&d, 1, "materials[0].density: must be > 0 (got -2)", "submit", path);
    CHECK(td_write(path,
                   "{\"grid\": {\"dim\": 2, \"spacing\": [0.01, 0.01], \"nodes\": [101, 101]},"
                   " \"materials\": [{\"youngsModulus\": 1, \"density\": 1}],"
                   " \"bodies\": [{\"box\": {\"lo\": [0, 0], \"hi\": [1, 1]}}], \"steps\": 1}") ==
          0);
    /* the solver's count stops at this server's --max-particles (the one
     * limit), naming the body that passed it */
    EXPECT_CTL(&d, 1, "TOO_LARGE: bodies[0]: the case has more than 5000 particles", "submit",
               path);
    CHECK(td_ctl(&d, 30, &o, "submit", path, NULL) == 0);
    CHECKF(strstr(o.err, "TOO_LARGE: bodies[0]: "), "mpmctl does not name the field: %s", o.err);
    td_out_free(&o);

    /* damaged requests and frames */
    {
        static const uint8_t garbage[] = {0xff, 0xff, 0xff, 0xff, 0xff, 0xff,
                                          0xff, 0xff, 0xff, 0xff, 0xff};
        static const uint8_t no_body[] = {0x08, 0x01};
        static const uint8_t v2_ping[] = {0x08, 0x02, 0x4a, 0x00};
        static const uint8_t ping[] = {0x08, 0x01, 0x4a, 0x00};
        static const uint8_t status_no_id[] = {0x08, 0x01, 0x22, 0x00};
        static const uint8_t list_bad_status[] = {0x08, 0x01, 0x2a, 0x02, 0x08, 0x63};
        static const uint8_t truncated[] = {0x08, 0x01, 0x12, 0x40, 0x0a};
        uint8_t *big = calloc(150000, 1);
        CHECK(big);
        {
            const void *f[] = {"", garbage};
            size_t l[] = {0, sizeof garbage};
            CHECK(frames_expect(&d, "garbage bytes", f, l, 2, "BAD_REQUEST", 0));
        }
        {
            const void *f[] = {"", truncated};
            size_t l[] = {0, sizeof truncated};
            CHECK(frames_expect(&d, "truncated request", f, l, 2, "BAD_REQUEST", 0));
        }
        {
            const void *f[] = {"", no_body};
            size_t l[] = {0, sizeof no_body};
            CHECK(frames_expect(&d, "request without a body", f, l, 2, "BAD_REQUEST", 0));
        }
        {
            const void *f[] = {"", status_no_id};
            size_t l[] = {0, sizeof status_no_id};
            CHECK(frames_expect(&d, "status without jobId", f, l, 2, "BAD_REQUEST", 0));
        }
        {
            const void *f[] = {"", list_bad_status};
            size_t l[] = {0, sizeof list_bad_status};
            CHECK(frames_expect(&d, "listRuns status 99", f, l, 2, "BAD_REQUEST", 0));
        }
        {
            const void *f[] = {"", v2_ping};
            size_t l[] = {0, sizeof v2_ping};
            CHECK(frames_expect(&d, "schemaVersion 2", f, l, 2, "BAD_SCHEMA", 0));
        }
        {
            const void *f[] = {"", ping, ping};
            size_t l[] = {0, sizeof ping, sizeof ping};
            CHECK(frames_expect(&d, "two request frames", f, l, 3, "BAD_REQUEST", 1));
        }
        {
            const void *f[] = {ping};
            size_t l[] = {sizeof ping};
            CHECK(frames_expect(&d, "no empty delimiter", f, l, 1, "BAD_REQUEST", 1));
        }
        {
            const void *f[] = {"", big};
            size_t l[] = {0, 150000};
            int ok = frames_expect(&d, "150000-byte request", f, l, 2, "TOO_LARGE", 0);
            free(big);
            CHECK(ok);
        }
    }
    /* unknown ids: NOT_FOUND naming the request's id field as the JSON
     * mapping spells it (as case errors name theirs), the id in the message */
    {
        static const struct {
            mpp_req_kind kind;
            int has_step;
            const char *what, *field;
        } unknown[] = {
            {MPP_REQ_STATUS, 0, "status{jobId: 4242}", "jobId"},
            {MPP_REQ_GET_RUN, 0, "getRun{runId: 4242}", "runId"},
            {MPP_REQ_GET_ENERGY, 0, "getEnergy{runId: 4242}", "runId"},
            {MPP_REQ_GET_SNAPSHOT, 0, "getSnapshot{runId: 4242}", "runId"},
            {MPP_REQ_GET_SNAPSHOT, 1, "getSnapshot{runId: 4242, step}", "runId"},
            {MPP_REQ_CANCEL, 0, "cancel{jobId: 4242}", "jobId"},
        };
        for (size_t i = 0; i < sizeof unknown / sizeof unknown[0]; i++) {
            mpp_request rq = {
                .kind = unknown[i].kind, .id = 4242, .has_step = unknown[i].has_step, .step = 10};
            CHECK(expect_not_found(&d, rq, unknown[i].what, unknown[i].field) == 0);
        }
        /* mpmctl shows the field */
        CHECK(td_ctl(&d, 30, &o, "show", "4242", NULL) == 0);
        CHECKF(o.status == 1 && strstr(o.err, "NOT_FOUND: runId: no run 4242\n"), "show 4242: %s",
               o.err);
        td_out_free(&o);
        CHECK(td_ctl(&d, 30, &o, "cancel", "4242", NULL) == 0);
        CHECKF(o.status == 1 && strstr(o.err, "NOT_FOUND: jobId: no job 4242\n"), "cancel 4242: %s",
               o.err);
        td_out_free(&o);
    }
    /* a listing above the server's maximum says so, naming the field and the limit */
    {
        mpp_request rq = {.kind = MPP_REQ_LIST_RUNS, .limit = 20000};
        json_t *reply = NULL;
        CHECK(td_request(d.ep, &rq, 10, &reply) == 0);
        CHECKF(!strcmp(td_err_code(reply), "TOO_LARGE") &&
                   !strcmp(td_err_field(reply), "listRuns.limit") &&
                   strstr(td_err_msg(reply), "10000"),
               "listRuns{limit: 20000}: %s, field \"%s\", %s", td_err_code(reply),
               td_err_field(reply), td_err_msg(reply));
        TLOG("listRuns{limit: 20000}         %s, field %s: %s", td_err_code(reply),
             td_err_field(reply), td_err_msg(reply));
        json_decref(reply);
    }
    /* a request that cannot be decoded names its missing field too */
    {
        static const uint8_t status_no_id[] = {0x08, 0x01, 0x22, 0x00};
        const void *f[] = {"", status_no_id};
        size_t l[] = {0, sizeof status_no_id};
        json_t *reply = NULL;
        CHECK(td_frames(d.ep, f, l, 2, 10, &reply) == 0);
        CHECKF(!strcmp(td_err_code(reply), "BAD_REQUEST") &&
                   !strcmp(td_err_field(reply), "status.jobId"),
               "status without jobId: %s, field \"%s\"", td_err_code(reply), td_err_field(reply));
        json_decref(reply);
    }

    /* still serving; nothing was recorded for the refused submissions */
    EXPECT_CTL(&d, 0, "schema 1", "ping");
    CHECK(td_ctl(&d, 30, &o, "runs", "--json", NULL) == 0);
    CHECKF(o.status == 0 && !o.out[0], "runs after refused submissions: %s", o.out);
    td_out_free(&o);
    CHECK(td_stop(&d) == 0);
}

/* A watched job's stream read with mpp_stream_decode: every message in seq
 * order (energies batched by the worker lose none and keep their order),
 * every energy sample once, and the snapshots - packed into one reused
 * buffer and handed to zmq without a copy - each holding the state of its
 * own step, as the solver in-process has it.  The watcher reads nothing
 * until the job has ended, so the snapshots (~0.8 MB each, more than the
 * socket buffers take) wait in zmq's queues while the next ones are
 * packed: a buffer reused while zmq still held it would show here. */
