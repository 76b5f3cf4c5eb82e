/*
 * t_codec_wire.c - the envelopes on the wire (mpp_request, mpp_reply,
 * mpp_stream) and the endpoint rules (mpp_endpoint): damaged bytes give
 * errors (not crashes), the Request / Reply / StreamMsg helpers encode
 * what they should, the size limits hold, and endpoints are classified as
 * the daemon's bind rule needs.  (The client decoders are tested in
 * t_codec_decode.c, the Python interoperability in t_codec_python.c.)
 */
#include "t.h"

#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#include "mpmd.pb-c.h"
#include "mpp_case.h"
#include "mpp_endpoint.h"
#include "mpp_json.h"
#include "mpp_msg.h"
#include "t_codec.h"
#include "t_daemon.h"

TEST(codec_bad_bytes)
{
    char err[T_ERRLEN];
    size_t len = 0, n = 0;
    uint8_t *buf = NULL;
    Mpmd__Case *pb = NULL;
    char *text = td_slurp("proto/examples/disks2d_coarse.json", &len);
    CHECK(text);
    int rc = td_case_from_json(text, len, &pb, err, sizeof err);
    free(text);
    CHECKF(rc == 0, "%s", err);
    rc = mpp_case_pack(pb, &buf, &n);
    mpp_case_pb_free(&pb);
    CHECK(rc == 0 && n > 20);

    int bad_prefix = 0, ok_prefix = 0;
    for (size_t k = 0; k < n; k++) {
        rc = td_case_unpack(buf, k, 0, &pb, err, sizeof err);
        if (rc) {
            if (rc != MPM_ESYNTAX || pb || !strstr(err, "not a valid mpmd.Case message")) break;
            bad_prefix++;
        } else {
            /* a prefix that ends between fields is a valid, smaller case */
            mpp_case *sc = NULL;
            ok_prefix++;
            if (!from_pb(pb, &sc, err)) mpp_case_destroy(&sc);
            mpp_case_pb_free(&pb);
        }
    }
    TLOG("%zu-byte case: %d truncations rejected, %d decode as smaller cases", n, bad_prefix,
         ok_prefix);
    CHECK(bad_prefix + ok_prefix == (int)n);
    CHECK(bad_prefix > (int)n / 2);

    /* every single-byte corruption: decode fails or yields a case that
     * converts or is rejected cleanly */
    int rejected = 0, decoded = 0;
    for (size_t k = 0; k < n; k++) {
        static const uint8_t vals[] = {0x00, 0xff, 0x80, 0x07, 0x12};
        for (size_t v = 0; v < sizeof vals; v++) {
            uint8_t save = buf[k];
            char *json = NULL;
            buf[k] = vals[v];
            rc = td_case_unpack(buf, n, 0, &pb, err, sizeof err);
            if (rc) {
                CHECK(rc == MPM_ESYNTAX && pb == NULL);
                rejected++;
            } else {
                mpp_case *sc = NULL;
                decoded++;
                if (!from_pb(pb, &sc, err)) mpp_case_destroy(&sc);
                if (!case_to_json(pb, 0, &json, err)) free(json);
                mpp_case_pb_free(&pb);
            }
            buf[k] = save;
        }
    }
    TLOG("corrupted bytes: %d rejected, %d decoded", rejected, decoded);
    CHECK(rejected > 0);

    static const uint8_t garbage[] = {0xff, 0xff, 0xff, 0xff, 0xff, 0xff,
                                      0xff, 0xff, 0xff, 0xff, 0xff};
    rc = td_case_unpack(garbage, sizeof garbage, 0, &pb, err, sizeof err);
    CHECK(rc == MPM_ESYNTAX && pb == NULL);
    /* a field 2 (grid) claiming 100 bytes with 2 present */
    static const uint8_t shortlen[] = {0x12, 100, 0x08, 0x01};
    rc = td_case_unpack(shortlen, sizeof shortlen, 0, &pb, err, sizeof err);
    CHECK(rc == MPM_ESYNTAX && pb == NULL);
    rc = td_case_unpack(buf, n, n - 1, &pb, err, sizeof err);
    CHECKF(rc == MPM_ETOOBIG && pb == NULL && strstr(err, "more than the limit"), "%s", err);
    /* unknown enum numbers survive protobuf decoding (appended fields
     * override / extend the valid case) but not the conversion */
    static const struct {
        uint8_t tail[8];
        size_t n;
        const char *want;
    } tails[] = {
        {{0x18, 0x05}, 2, "method: unknown value 5"}, /* method = 5 */
        {{0x20, 0x03}, 2, "update: unknown value 3"}, /* update = 3 */
        {{0x8a, 0x01, 0x03, 0x1a, 0x01, 0x09}, 6, "output.snapshotFields[3]: unknown value 9"},
        {{0x52, 0x02, 0x08, 0x09},
         4,
         "materials[1].model: unknown value 9"}, /* materials += {model: 9} */
    };
    for (size_t i = 0; i < sizeof tails / sizeof tails[0]; i++) {
        uint8_t *b2 = malloc(n + tails[i].n);
        mpp_case *sc = NULL;
        CHECK(b2);
        memcpy(b2, buf, n);
        memcpy(b2 + n, tails[i].tail, tails[i].n);
        rc = td_case_unpack(b2, n + tails[i].n, 0, &pb, err, sizeof err);
        free(b2);
        CHECKF(rc == 0 && pb, "tail %zu: %s", i, err);
        rc = from_pb(pb, &sc, err);
        mpp_case_pb_free(&pb);
        CHECKF(rc == MPM_EINVAL && sc == NULL && strstr(err, tails[i].want), "tail %zu: %s", i,
               err);
        TLOG("%s", err);
    }
    free(buf);
}

/* Request decoding and Reply / StreamMsg encoding. */
TEST(codec_envelopes)
{
    char err[T_ERRLEN];
    uint8_t *buf = NULL;
    size_t n = 0;
    mpp_request rq;
    char *json = NULL;
    int rc;

    /* Submit carrying a case */
    char *caseText = NULL;
    size_t clen = 0;
    caseText = td_slurp("proto/examples/point1d.json", &clen);
    CHECK(caseText);
    size_t rlen = clen + 64;
    char *req = malloc(rlen);
    CHECK(req);
    snprintf(req, rlen, "{\"schemaVersion\": 1, \"submit\": {\"case\": %s}}", caseText);
    free(caseText);
    rc = td_msg_json_to_bytes(MPP_MSG_REQUEST, req, strlen(req), &buf, &n, err, sizeof err);
    free(req);
    CHECKF(rc == 0, "%s", err);
    rc = req_decode(buf, n, 0, &rq, err);
    free(buf);
    CHECKF(rc == 0, "%s", err);
    CHECK(rq.kind == MPP_REQ_SUBMIT && rq.case_pb);
    {
        mpp_case *sc = NULL;
        rc = from_pb(rq.case_pb, &sc, err);
        mpp_request_clear(&rq);
        CHECKF(rc == 0, "%s", err);
        CHECK(sc->c.bodies[0].n_points == 1);
        mpp_case_destroy(&sc);
    }

    static const struct {
        const char *json;
        int rc;
        mpp_req_kind kind;
        uint64_t id;
        const char *err;
    } reqs[] = {
        {"{\"schemaVersion\": 1, \"cancel\": {\"jobId\": \"18446744073709551615\"}}", 0,
         MPP_REQ_CANCEL, UINT64_MAX, ""},
        {"{\"schemaVersion\": 1, \"status\": {\"jobId\": 7}}", 0, MPP_REQ_STATUS, 7, ""},
        {"{\"schemaVersion\": 1, \"listRuns\": {\"status\": \"FAILED\", \"limit\": 5}}", 0,
         MPP_REQ_LIST_RUNS, 0, ""},
        {"{\"schemaVersion\": 1, \"getRun\": {\"runId\": 3, \"withCase\": true}}", 0,
         MPP_REQ_GET_RUN, 3, ""},
        {"{\"schemaVersion\": 1, \"getEnergy\": {\"runId\": 3, \"fromSeq\": 10}}", 0,
         MPP_REQ_GET_ENERGY, 3, ""},
        {"{\"schemaVersion\": 1, \"getSnapshot\": {\"runId\": 4, \"step\": \"-1\"}}", 0,
         MPP_REQ_GET_SNAPSHOT, 4, ""},
        {"{\"schemaVersion\": 1, \"ping\": {}}", 0, MPP_REQ_PING, 0, ""},
        {"{\"schemaVersion\": 1, \"version\": {}}", 0, MPP_REQ_VERSION, 0, ""},
        {"{\"schemaVersion\": 2, \"ping\": {}}", MPM_EVERSION, 0, 0,
         "schemaVersion: 2; this server speaks 1"},
        {"{\"ping\": {}}", MPM_EVERSION, 0, 0, "schemaVersion: missing"},
        {"{\"schemaVersion\": 1}", MPM_EREQUEST, 0, 0, "request: no body"},
        {"{\"schemaVersion\": 1, \"cancel\": {}}", MPM_EREQUEST, 0, 0, "cancel.jobId: missing"},
        {"{\"schemaVersion\": 1, \"submit\": {}}", MPM_EREQUEST, 0, 0, "submit.case: missing"},
    };
    for (size_t i = 0; i < sizeof reqs / sizeof reqs[0]; i++) {
        rc = td_msg_json_to_bytes(MPP_MSG_REQUEST, reqs[i].json, strlen(reqs[i].json), &buf, &n,
                                  err, sizeof err);
        CHECKF(rc == 0, "%s: %s", reqs[i].json, err);
        err[0] = 0;
        rc = req_decode(buf, n, 0, &rq, err);
        free(buf);
        int ok = rc == reqs[i].rc && strstr(err, reqs[i].err) &&
                 (rc || (rq.kind == reqs[i].kind && rq.id == reqs[i].id));
        if (ok && rq.kind == MPP_REQ_LIST_RUNS)
            ok = rq.status == MPP_STATUS_FAILED && rq.limit == 5;
        if (ok && rq.kind == MPP_REQ_GET_RUN) ok = rq.with_case == 1;
        if (ok && rq.kind == MPP_REQ_GET_ENERGY) ok = rq.from_seq == 10;
        if (ok && rq.kind == MPP_REQ_GET_SNAPSHOT) ok = rq.has_step && rq.step == -1;
        mpp_request_clear(&rq);
        CHECKF(ok, "%s: rc %d, kind %d, id %llu, err \"%s\"", reqs[i].json, rc, (int)rq.kind,
               (unsigned long long)rq.id, err);
    }
    static const uint8_t junk[] = {0x0a, 0xff, 0xff};
    CHECK(req_decode(junk, sizeof junk, 0, &rq, err) == MPM_ESYNTAX);
    mpp_request_clear(&rq);
    CHECK(req_decode(junk, sizeof junk, 2, &rq, err) == MPM_ETOOBIG);
    mpp_request_clear(&rq);

    /* replies, checked through their JSON form */
    mpm_energy_sample es = {.step = 10,
                            .t = 0.01,
                            .dim = 2,
                            .seq = 3,
                            .e = {.kinetic = 0.5,
                                  .strain = 0.25,
                                  .total = 0.75,
                                  .mass = 2,
                                  .momentum = {1, -1, 9},
                                  .angular_momentum = {7, 8, -0.125}}}; /* 2D: z alone goes out */
    double x[4] = {0.1, 0.2, 0.3, 0.4}, p[2] = {-1, 1};
    mpp_snapshot snap = {.step = 10, .t = 0.01, .n = 2, .dim = 2, .x = x, .pressure = p};
    int64_t ssteps[2] = {0, 100};
    uint8_t *cb = NULL;
    size_t cn = 0;
    {
        Mpmd__Case *cpb = NULL;
        const char *cj = "{\"name\": \"c\", \"steps\": 3}";
        CHECK(td_case_from_json(cj, strlen(cj), &cpb, err, sizeof err) == 0);
        CHECK(mpp_case_pack(cpb, &cb, &cn) == 0);
        mpp_case_pb_free(&cpb);
    }
    mpp_run_info ri = {.run_id = 5,
                       .job_id = 6,
                       .name = "bar",
                       .status = MPP_STATUS_RUNNING,
                       .submitted_at = 1700000000.5,
                       .steps = 10,
                       .steps_total = 100,
                       .t = 0.01,
                       .dim = 2,
                       .last_energy = &es,
                       .n_snapshot_steps = 2,
                       .snapshot_steps = ssteps,
                       .method = MPM_METHOD_GIMP,
                       .update = MPM_USL,
                       .transfer = MPM_TRANSFER_APIC,
                       .case_bytes = cb,
                       .case_len = cn};
    mpp_run_info two[2] = {ri, ri};
    two[1].run_id = 9;
    two[1].case_bytes = NULL;
    two[1].error = "particle left the grid";
    two[1].status = MPP_STATUS_FAILED;
    const char *names[2] = {"protobuf-c", "jansson"}, *versions[2] = {"1.4.1", "2.14"};
    mpp_progress pr = {.step = 5, .steps_total = 50, .t = 0.5, .dt = 0.1, .wall_s = 0.25};
    mpp_finished fin = {
        .status = MPP_STATUS_FINISHED, .steps = 50, .t = 5, .wall_s = 1, .energy = &es};

    static const char *const want[] = {
        "{\"schemaVersion\":1,\"error\":{\"code\":\"INVALID_CASE\",\"message\":\"must be > 0\",\"field\":\"bodies[0].sphere.radius\"}}",
        "{\"schemaVersion\":1,\"submitOk\":{\"jobId\":\"12\",\"runId\":\"13\"}}",
        "{\"schemaVersion\":1,\"run\":{\"runId\":\"5\",\"jobId\":\"6\",\"name\":\"bar\",\"status\":\"RUNNING\","
        "\"submittedAt\":1700000000.5,\"steps\":\"10\",\"stepsTotal\":\"100\",\"t\":0.01,\"wallS\":0,"
        "\"particles\":\"0\",\"nodes\":\"0\",\"dim\":2,\"lastEnergy\":{\"step\":\"10\",\"t\":0.01,\"kinetic\":0.5,"
        "\"strain\":0.25,\"potential\":0,\"externalWork\":0,\"total\":0.75,\"momentum\":[1,-1],\"mass\":2,"
        "\"seq\":\"3\",\"angularMomentum\":[-0.125]},\"energySamples\":\"0\",\"snapshotSteps\":[\"0\",\"100\"],\"case\":{\"name\":\"c\","
        "\"method\":\"GIMP\",\"update\":\"USL\",\"steps\":\"3\",\"transfer\":\"APIC\"},\"method\":\"GIMP\",\"update\":\"USL\","
        "\"transfer\":\"APIC\"}}",
        "\"runId\":\"9\",\"jobId\":\"6\",\"name\":\"bar\",\"status\":\"FAILED\",\"error\":\"particle left the grid\"",
        "{\"schemaVersion\":1,\"energy\":{\"runId\":\"5\",\"samples\":[{\"step\":\"10\"",
        "{\"schemaVersion\":1,\"snapshot\":{\"step\":\"10\",\"t\":0.01,\"n\":\"2\",\"dim\":2,\"x\":[0.1,0.2,0.3,0.4],"
        "\"pressure\":[-1,1]}}",
        "{\"schemaVersion\":1,\"pong\":{\"serverVersion\":\"0.1\",\"schemaVersion\":1,"
        "\"streamEndpoint\":\"tcp://127.0.0.1:5556\",\"schemaMinor\":1}}",
        "{\"schemaVersion\":1,\"version\":{\"serverVersion\":\"0.1\",\"schemaVersion\":1,\"components\":[{\"name\":"
        "\"protobuf-c\",\"version\":\"1.4.1\"},{\"name\":\"jansson\",\"version\":\"2.14\"}],"
        "\"schemaMinor\":1}}",
        "{\"jobId\":\"12\",\"seq\":\"0\",\"progress\":{\"step\":\"5\",\"t\":0.5,\"dt\":0.1,\"stepsTotal\":\"50\",\"wallS\":0.25}}",
        "{\"jobId\":\"12\",\"seq\":\"1\",\"energy\":{\"step\":\"10\",",
        "{\"jobId\":\"12\",\"seq\":\"2\",\"snapshot\":{\"step\":\"10\"",
        "{\"jobId\":\"12\",\"seq\":\"3\",\"finished\":{\"status\":\"FINISHED\",\"steps\":\"50\",\"t\":5,\"wallS\":1,\"energy\":{",
    };
    for (size_t i = 0; i < sizeof want / sizeof want[0]; i++) {
        mpp_msg_kind kind = i < 8 ? MPP_MSG_REPLY : MPP_MSG_STREAM;
        switch (i) {
        case 0:
            rc = mpp_reply_error(MPP_ERR_INVALID_CASE, "must be > 0", "bodies[0].sphere.radius",
                                 &buf, &n);
            break;
        case 1: rc = mpp_reply_submit_ok(12, 13, &buf, &n); break;
        case 2: rc = mpp_reply_run(&ri, &buf, &n); break;
        case 3: rc = mpp_reply_runs(two, 2, &buf, &n); break;
        case 4: rc = mpp_reply_energy(5, &es, 1, 0, &buf, &n); break;
        case 5: rc = mpp_reply_snapshot(&snap, &buf, &n); break;
        case 6: rc = mpp_reply_pong("0.1", "tcp://127.0.0.1:5556", &buf, &n); break;
        case 7: rc = mpp_reply_version("0.1", names, versions, 2, &buf, &n); break;
        case 8: rc = mpp_stream_progress(12, 0, &pr, &buf, &n); break;
        case 9: rc = mpp_stream_energy(12, 1, &es, &buf, &n); break;
        case 10: rc = mpp_stream_snapshot(12, 2, &snap, &buf, &n); break;
        default: rc = mpp_stream_finished(12, 3, &fin, &buf, &n); break;
        }
        CHECKF(rc == 0, "encoder %zu: rc %d", i, rc);
        rc = td_msg_bytes_to_json(kind, buf, n, 0, 0, &json, err, sizeof err);
        free(buf);
        CHECKF(rc == 0, "encoder %zu: %s", i, err);
        int ok = strstr(json, want[i]) != NULL;
        if (i == 3) ok = ok && strstr(json, "\"runs\":{\"runs\":[{\"runId\":\"5\"");
        if (!ok) TLOG("got  %s\nwant %s", json, want[i]);
        free(json);
        CHECKF(ok, "encoder %zu", i);
    }
    free(cb);
    /* case bytes that are not a Case */
    ri.case_bytes = junk;
    ri.case_len = sizeof junk;
    CHECK(mpp_reply_run(&ri, &buf, &n) == MPM_ESYNTAX && buf == NULL);

    CHECK(!strcmp(mpp_status_name(MPP_STATUS_INTERRUPTED), "INTERRUPTED") && !mpp_status_name(0));
    CHECK(mpp_status_from_name("CANCELLED") == MPP_STATUS_CANCELLED &&
          mpp_status_from_name("x") == 0);
}

TEST(codec_endpoints)
{
    char out[64];
    static const struct {
        const char *ep;
        int local, wildcard;
    } eps[] = {
        {"ipc:///tmp/x", 1, 0},          {"inproc://a", 1, 0},
        {"tcp://127.0.0.1:5555", 1, 0},  {"tcp://127.1.2.3:1", 1, 0},
        {"tcp://localhost:5555", 1, 0},  {"tcp://[::1]:5555", 1, 0},
        {"tcp://ip6-localhost:9", 1, 0}, {"tcp://*:5555", 0, 1},
        {"tcp://0.0.0.0:5555", 0, 1},    {"tcp://[::]:5555", 0, 1},
        {"tcp://10.0.0.1:5555", 0, 0},   {"tcp://example.org:5555", 0, 0},
        {"udp://127.0.0.1:5", 0, 0},     {"tcp://localhostx:5", 0, 0},
    };
    for (size_t i = 0; i < sizeof eps / sizeof eps[0]; i++)
        CHECKF(mpp_endpoint_is_local(eps[i].ep) == eps[i].local &&
                   mpp_endpoint_is_wildcard(eps[i].ep) == eps[i].wildcard,
               "%s", eps[i].ep);
    CHECK(mpp_stream_endpoint_derive("tcp://127.0.0.1:5555", out, sizeof out) == 0 &&
          !strcmp(out, "tcp://127.0.0.1:5556"));
    CHECK(mpp_stream_endpoint_derive("ipc:///tmp/m", out, sizeof out) == 0 &&
          !strcmp(out, "ipc:///tmp/m.stream"));
    CHECK(mpp_stream_endpoint_derive("tcp://h:65535", out, sizeof out) == -1);
    CHECK(mpp_stream_endpoint_derive("tcp://h:0", out, sizeof out) == -1);
    CHECK(mpp_stream_endpoint_derive("tcp://h:12x", out, sizeof out) == -1);
    CHECK(mpp_stream_endpoint_derive("tcp://h", out, sizeof out) == -1);
    CHECK(mpp_stream_endpoint_derive("inproc://a", out, sizeof out) == -1);
    CHECK(mpp_stream_endpoint_derive("tcp://127.0.0.1:5555", out, 10) == -1);
    /* a client: the reported endpoint unless only the daemon's machine can use it */
    CHECK(mpp_stream_endpoint_for_client("tcp://10.0.0.1:7000", "tcp://10.0.0.1:5555", out,
                                         sizeof out) == 0 &&
          !strcmp(out, "tcp://10.0.0.1:7000"));
    CHECK(mpp_stream_endpoint_for_client("tcp://*:5556", "tcp://server:5555", out, sizeof out) ==
              0 &&
          !strcmp(out, "tcp://server:5556"));
    CHECK(mpp_stream_endpoint_for_client("tcp://127.0.0.1:5556", "tcp://server:5555", out,
                                         sizeof out) == 0 &&
          !strcmp(out, "tcp://server:5556"));
    CHECK(mpp_stream_endpoint_for_client("ipc:///tmp/s", "tcp://server:5555", out, sizeof out) ==
              0 &&
          !strcmp(out, "ipc:///tmp/s"));
    CHECK(mpp_stream_endpoint_for_client("", "ipc:///tmp/c", out, sizeof out) == 0 &&
          !strcmp(out, "ipc:///tmp/c.stream"));
    CHECK(mpp_stream_endpoint_for_client(NULL, "inproc://x", out, sizeof out) == -1);
}

/* A Submit around case bytes packed beforehand is the very Request the
 * case message would give. */
TEST(codec_submit_bytes)
{
    char err[T_ERRLEN];
    size_t len = 0, cn = 0, n1 = 0, n2 = 0;
    uint8_t *cb = NULL, *b1 = NULL, *b2 = NULL;
    Mpmd__Case *pb = NULL;
    char *text = td_slurp("proto/examples/disks2d_coarse.json", &len);
    CHECK(text);
    int rc = td_case_from_json(text, len, &pb, err, sizeof err);
    free(text);
    CHECKF(rc == 0, "%s", err);
    CHECK(mpp_case_pack(pb, &cb, &cn) == 0 && cn > 127); /* a two-byte length */
    mpp_request rq = {.kind = MPP_REQ_SUBMIT, .case_pb = pb};
    rc = mpp_request_encode(&rq, &b1, &n1);
    mpp_case_pb_free(&pb);
    CHECK(rc == 0);
    mpp_request rb = {.kind = MPP_REQ_SUBMIT, .case_bytes = cb, .case_len = cn};
    rc = mpp_request_encode(&rb, &b2, &n2);
    int same = rc == 0 && n1 == n2 && !memcmp(b1, b2, n1);
    free(b1);
    CHECK(same);
    /* and it decodes back to the same case */
    mpp_request got;
    rc = req_decode(b2, n2, 0, &got, err);
    free(b2);
    CHECKF(rc == 0 && got.kind == MPP_REQ_SUBMIT && got.case_pb, "%s", err);
    uint8_t *again = NULL;
    size_t an = 0;
    rc = mpp_case_pack(got.case_pb, &again, &an);
    mpp_request_clear(&got);
    same = rc == 0 && an == cn && !memcmp(again, cb, cn);
    free(again);
    CHECK(same);
    /* an empty case, another schema version */
    rb.case_len = 0;
    rb.schema_version = 300;
    CHECK(mpp_request_encode(&rb, &b2, &n2) == 0);
    rc = req_decode(b2, n2, 0, &got, err);
    free(b2);
    CHECK(rc == MPM_EVERSION && got.schema_version == 300);
    mpp_request_clear(&got);
    rb.schema_version = 0;
    CHECK(mpp_request_encode(&rb, &b2, &n2) == 0);
    rc = req_decode(b2, n2, 0, &got, err);
    free(b2);
    CHECK(rc == 0 && got.kind == MPP_REQ_SUBMIT && got.case_pb);
    mpp_request_clear(&got);
    /* no case at all */
    rb.case_bytes = NULL;
    CHECK(mpp_request_encode(&rb, &b2, &n2) == MPM_EINVAL && !b2);
    free(cb);
}
