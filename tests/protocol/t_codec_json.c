/*
 * t_codec_json.c - the generic JSON <-> protobuf converter (mpp_json) and
 * the case check: cases survive JSON -> protobuf -> bytes -> JSON
 * unchanged, the JSON mapping's spellings, bad JSON and bad cases rejected
 * with the JSON path of the offending field, the defaults filled in, and
 * the names of methods, updates and transfers matching the schema's.
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

/* mpp_case_load of a JSON text, returning the code and the error text. */
static int load_text(const char *json, char *err)
{
    mpp_case *sc = NULL;
    int rc = td_case_load(json, strlen(json), &sc, err, T_ERRLEN);
    mpp_case_destroy(&sc);
    return rc;
}

/* Expects the patched td_good2d to fail with rc and an error containing
 * want; returns 0 or 1 on mismatch (after reporting it). */
static int expect_bad(const char *from, const char *to, int rc_want, const char *want)
{
    char err[T_ERRLEN] = "";
    char *json = td_patch(from, to);
    int rc;
    if (!json) {
        t_fail(__FILE__, __LINE__, "patch: \"%s\" not in the base case", from);
        return 1;
    }
    rc = load_text(json, err);
    free(json);
    if (rc != rc_want || !strstr(err, want)) {
        t_fail(__FILE__, __LINE__, "%s -> %s: rc %d (want %d), error \"%s\" (want \"%s\")", from,
               to, rc, rc_want, err, want);
        return 1;
    }
    TLOG("%-44.44s -> %s", to, err);
    return 0;
}

/* JSON -> pb -> bytes -> pb -> JSON -> pb -> bytes: same bytes. */
TEST(codec_roundtrip)
{
    static const char *const names[] = {"point1d",        "bar1d_mpm",          "bar1d_gimp",
                                        "disks2d_coarse", "disks2d_fine",       "cube3d",
                                        "bar1d_bspline2", "disks2d_bspline2",   "hangbar2d_cpdi",
                                        "disk2d_apic",    "sliding_block",      "pushed_bar1d",
                                        "impact2d_j2",    "column2d_geostatic", "triaxial3d_mc",
                                        "collapse2d"};
    for (size_t k = 0; k < sizeof names / sizeof names[0]; k++) {
        char path[256], err[T_ERRLEN];
        size_t len = 0, n1 = 0, n2 = 0;
        uint8_t *b1 = NULL, *b2 = NULL;
        char *json = NULL, *compact = NULL;
        Mpmd__Case *p1 = NULL, *p2 = NULL, *p3 = NULL, *p4 = NULL;
        int ok = 0;
        snprintf(path, sizeof path, "proto/examples/%s.json", names[k]);
        char *text = td_slurp(path, &len);
        if (text && !td_case_from_json(text, len, &p1, err, sizeof err) &&
            !mpp_case_pack(p1, &b1, &n1) && !td_case_unpack(b1, n1, 0, &p2, err, sizeof err) &&
            !case_to_json(p2, MPP_JSON_PRETTY, &json, err) &&
            !td_case_from_json(json, strlen(json), &p3, err, sizeof err) &&
            !mpp_case_pack(p3, &b2, &n2) && !case_to_json(p3, 0, &compact, err) &&
            !td_case_from_json(compact, strlen(compact), &p4, err, sizeof err))
            ok = 1;
        if (ok)
            TLOG("%s: %zu bytes JSON, %zu bytes protobuf, %zu bytes compact JSON", names[k], len,
                 n1, strlen(compact));
        int same = ok && n1 == n2 && !memcmp(b1, b2, n1);
        /* the examples are in the pretty printer's canonical form */
        int same_text = ok && !strcmp(json, text);
        free(text);
        free(b1);
        free(b2);
        free(json);
        free(compact);
        mpp_case_pb_free(&p1);
        mpp_case_pb_free(&p2);
        mpp_case_pb_free(&p3);
        mpp_case_pb_free(&p4);
        CHECKF(ok, "%s: %s", names[k], err);
        CHECKF(same, "%s: bytes differ after the round trip (%zu vs %zu)", names[k], n1, n2);
        CHECKF(same_text, "%s: printed JSON differs from the file", names[k]);
        CHECK(p1 == NULL && p4 == NULL);
    }
}

/* Mapping details: snake_case names, 64-bit integers as strings, the
 * special float strings, null = absent, enum numbers. */
TEST(codec_json_mapping)
{
    char err[T_ERRLEN];
    Mpmd__Case *pb = NULL;
    char *out = NULL;
    mpp_case *sc = NULL;
    const char *in =
        "{\"grid\": {\"dim\": 1, \"spacing\": [\"0.5\"], \"nodes\": [3], \"origin\": null},"
        " \"method\": 1, \"update\": \"MUSL\", \"mass_tol\": 1e-8, \"cfl\": null,"
        " \"materials\": [{\"youngs_modulus\": 2, \"density\": 1}],"
        " \"bodies\": [{\"box\": {\"lo\": [0.25], \"hi\": [0.75]}, \"ppc\": 3}],"
        " \"gravity\": [\"-Infinity\"], \"steps\": \"100\", \"threads\": 2.0}";
    int rc = td_case_from_json(in, strlen(in), &pb, err, sizeof err);
    CHECKF(rc == 0, "%s", err);
    rc = case_to_json(pb, 0, &out, err);
    CHECKF(rc == 0, "%s", err);
    TLOG("%s", out);
    const char *want =
        "{\"grid\":{\"dim\":1,\"spacing\":[0.5],\"nodes\":[3]},\"method\":\"GIMP\",\"update\":\"MUSL\","
        "\"massTol\":1e-08,\"gravity\":[\"-Infinity\"],\"materials\":[{\"youngsModulus\":2,\"density\":1}],"
        "\"bodies\":[{\"box\":{\"lo\":[0.25],\"hi\":[0.75]},\"ppc\":3}],\"steps\":\"100\",\"threads\":2}";
    int same = !strcmp(out, want);
    free(out);
    /* gravity -inf is schema-valid JSON but not a valid case */
    rc = from_pb(pb, &sc, err);
    mpp_case_pb_free(&pb);
    CHECKF(same, "got %s", want);
    CHECK(rc == MPM_EINVAL && sc == NULL);
    CHECKF(strstr(err, "gravity[0]: must be a finite number"), "%s", err);

    /* the same without gravity converts, with the snake_case and string values */
    const char *in2 =
        "{\"grid\": {\"dim\": 1, \"spacing\": [\"0.5\"], \"nodes\": [3]}, \"method\": 1,"
        " \"materials\": [{\"youngs_modulus\": 2, \"density\": 1}],"
        " \"bodies\": [{\"box\": {\"lo\": [0.25], \"hi\": [0.75]}, \"ppc\": 3}], \"steps\": \"100\"}";
    rc = td_case_load(in2, strlen(in2), &sc, err, sizeof err);
    CHECKF(rc == 0, "%s", err);
    CHECK(sc->c.method == MPM_METHOD_GIMP && sc->c.grid.h[0] == 0.5 && sc->c.bodies[0].ppc == 3);
    CHECK(!sc->has_end_time && sc->steps == 100);
    CHECK(sc->c.materials[0].youngs_modulus == 2);
    mpp_case_destroy(&sc);

    /* picFraction (or pic_fraction) arrives in mpm_case; absent is 0, pure FLIP */
    const char *in3 =
        "{\"grid\": {\"dim\": 1, \"spacing\": [\"0.5\"], \"nodes\": [3]}, \"picFraction\": 0.25,"
        " \"materials\": [{\"youngs_modulus\": 2, \"density\": 1}],"
        " \"bodies\": [{\"box\": {\"lo\": [0.25], \"hi\": [0.75]}, \"ppc\": 3}], \"steps\": \"100\"}";
    rc = td_case_load(in3, strlen(in3), &sc, err, sizeof err);
    CHECKF(rc == 0, "%s", err);
    CHECK(sc->c.pic_fraction == 0.25);
    mpp_case_destroy(&sc);
    rc = td_case_load(in2, strlen(in2), &sc, err, sizeof err);
    CHECKF(rc == 0, "%s", err);
    CHECK(sc->c.pic_fraction == 0);
    mpp_case_destroy(&sc);
    /* out of range: refused with the field named in the JSON spelling */
    char in4[1024];
    snprintf(in4, sizeof in4, "%s", in3);
    memcpy(strstr(in4, "0.25"), "1.50", 4);
    rc = td_case_load(in4, strlen(in4), &sc, err, sizeof err);
    CHECK(rc == MPM_EINVAL && sc == NULL);
    CHECKF(strstr(err, "must be in [0, 1]") && strstr(err, "(got 1.5)"), "%s", err);
    TLOG("picFraction 1.5: %s", err);

    CHECK(mpp_json_name("youngs_modulus", err, sizeof err) == 13 && !strcmp(err, "youngsModulus"));
    CHECK(mpp_json_name("x_lo", err, 3) == 3 && !strcmp(err, "xL"));
}

/* Schema errors: each names the JSON path of the bad value. */
TEST(codec_bad_json)
{
    const int S = MPM_EINVAL;
    if (expect_bad("\"youngsModulus\": 1", "\"youngsModulus\": \"ten\"", S,
                   "materials[0].youngsModulus: expected a number, got string \"ten\""))
        return;
    if (expect_bad("\"youngsModulus\": 1", "\"youngsModulus\": 1, \"colour\": \"red\"", S,
                   "materials[0].colour: unknown field"))
        return;
    if (expect_bad(
            "\"velocity\": [-0.1, 0]", "\"velocity\": [-0.1, 0], \"colour\": 1", S,
            "bodies[1].colour: unknown field (Body has: material, velocity, box, sphere, points, ppc, geostatic)"))
        return;
    if (expect_bad(
            "\"endTime\": 1", "\"endTime\": 1, \"method\": \"FEM\"", S,
            "method: unknown value string \"FEM\" for enum mpmd.Case.Method (expected one of: MPM, GIMP, BSPLINE2, BSPLINE3, CPDI)"))
        return;
    if (expect_bad("\"endTime\": 1", "\"endTime\": 1, \"update\": 7", S,
                   "update: unknown value number 7 for enum mpmd.Case.Update"))
        return;
    if (expect_bad("\"radius\": 0.1", "\"radius\": [0.1]", S,
                   "bodies[0].sphere.radius: expected a number, got array"))
        return;
    if (expect_bad("\"hi\": [0.8, 0.8]", "\"hi\": [0.8, true]", S,
                   "bodies[1].box.hi[1]: expected a number, got boolean true"))
        return;
    if (expect_bad("\"nodes\": [11, 11]", "\"nodes\": [11, -11]", S,
                   "grid.nodes[1]: expected a non-negative integer, got -11"))
        return;
    if (expect_bad("\"nodes\": [11, 11]", "\"nodes\": [11, 4294967296]", S,
                   "grid.nodes[1]: number 4294967296 out of range for uint32"))
        return;
    if (expect_bad("\"nodes\": [11, 11]", "\"nodes\": [11, 11.5]", S,
                   "grid.nodes[1]: expected an integer, got number 11.5"))
        return;
    if (expect_bad("\"nodes\": [11, 11]", "\"nodes\": [11, null]", S,
                   "grid.nodes[1]: null is not allowed in an array"))
        return;
    if (expect_bad("\"dim\": 2", "\"dim\": \"two\"", S,
                   "grid.dim: expected an integer, got string \"two\""))
        return;
    if (expect_bad("\"grid\": {", "\"grid\": [], \"x\": {", S,
                   "grid: expected an object, got array"))
        return;
    if (expect_bad("\"endTime\": 1", "\"endTime\": 1, \"steps\": 5", S,
                   "steps: only one member of a oneof may be set, and \"endTime\" is set already"))
        return;
    if (expect_bad(
            "\"sphere\": {", "\"box\": {}, \"sphere\": {", S,
            "bodies[0].sphere: only one member of a oneof may be set, and \"box\" is set already"))
        return;
    if (expect_bad(
            "\"density\": 1", "\"density\": 1, \"youngs_modulus\": 3", S,
            "materials[0].youngsModulus: field given twice (as \"youngs_modulus\" and \"youngsModulus\")"))
        return;
    if (expect_bad("\"endTime\": 1",
                   "\"endTime\": 1, \"boundary\": {\"nodes\": [{\"ijk\": [1, \"a\"]}]}", S,
                   "boundary.nodes[0].ijk[1]: expected an integer, got string \"a\""))
        return;
    if (expect_bad("\"endTime\": 1",
                   "\"endTime\": 1, \"output\": {\"snapshotFields\": [\"X\", \"Q\"]}", S,
                   "output.snapshotFields[1]: unknown value string \"Q\""))
        return;
    if (expect_bad("\"endTime\": 1", "\"endTime\": 1, \"name\": 5", S,
                   "name: expected a string, got number 5"))
        return;
    if (expect_bad("\"endTime\": 1", "\"endTime\": 1, \"allowUnstableDt\": 1", S,
                   "allowUnstableDt: expected true or false, got number 1"))
        return;
    if (expect_bad("{\"grid\"", "[{\"grid\"", MPM_ESYNTAX, "invalid JSON at line 1")) return;
    if (expect_bad("\"endTime\": 1}", "\"endTime\": 1,}", MPM_ESYNTAX, "invalid JSON at line 1"))
        return;
    if (expect_bad("\"endTime\": 1", "\"endTime\": 1, \"endTime\": 2", MPM_ESYNTAX, "duplicate"))
        return;
    {
        char err[T_ERRLEN];
        CHECK(load_text("[1, 2]", err) == MPM_EINVAL);
        CHECKF(strstr(err, "expected a JSON object (Case), got array"), "%s", err);
    }
}

/* Case errors the schema cannot catch, again naming the field. */
TEST(codec_bad_case)
{
    const int I = MPM_EINVAL;
    char err[T_ERRLEN];
    /* the base case itself is fine */
    CHECKF(load_text(td_good2d, err) == 0, "%s", err);
    if (expect_bad("\"radius\": 0.1", "\"radius\": 0", I, "bodies[0].sphere.radius: must be > 0"))
        return;
    if (expect_bad("\"radius\": 0.1", "\"radius\": \"NaN\"", I,
                   "bodies[0].sphere.radius: must be > 0"))
        return;
    if (expect_bad(", \"radius\": 0.1", "", I, "bodies[0].sphere.radius: missing")) return;
    if (expect_bad("\"center\": [0.3, 0.3]", "\"center\": [0.3]", I,
                   "bodies[0].sphere.center: expected 2 values (one per axis), got 1"))
        return;
    if (expect_bad("\"velocity\": [-0.1, 0]", "\"velocity\": [-0.1, 0], \"material\": 3", I,
                   "bodies[1].material: no material 3 (the case has 1)"))
        return;
    if (expect_bad("\"hi\": [0.8, 0.8]", "\"hi\": [0.8, 0.6]", I,
                   "bodies[1].box.hi[1]: must be > lo[1]"))
        return;
    if (expect_bad("\"velocity\": [-0.1, 0]", "\"velocity\": [-0.1, 0], \"ppc\": 9", I,
                   "bodies[1].ppc: must be 1..8 (got 9)"))
        return;
    if (expect_bad("{\"box\": {\"lo\": [0.6, 0.6], \"hi\": [0.8, 0.8]}, ", "{", I,
                   "bodies[1]: needs one of box, sphere or points"))
        return;
    if (expect_bad("\"endTime\": 1", "\"endTime\": 1, \"transfer\": \"APIC\", \"picFraction\": 0.5",
                   I, "picFraction: must be 0 (or absent) with transfer APIC"))
        return;
    if (expect_bad(
            "\"endTime\": 1", "\"endTime\": 1, \"transfer\": \"RPIC\"", I,
            "transfer: unknown value string \"RPIC\" for enum mpmd.Case.Transfer (expected one of: FLIP, APIC)"))
        return;
    if (expect_bad("\"dim\": 2", "\"dim\": 4", I, "grid.dim: must be 1, 2 or 3 (got 4)")) return;
    if (expect_bad("\"dim\": 2, ", "", I, "grid.dim: missing")) return;
    if (expect_bad("\"spacing\": [0.1, 0.1]", "\"spacing\": [0.1, -0.1]", I,
                   "grid.spacing[1]: must be > 0"))
        return;
    if (expect_bad("\"nodes\": [11, 11]", "\"nodes\": [11, 1]", I, "grid.nodes[1]: must be >= 2"))
        return;
    if (expect_bad("\"nodes\": [11, 11]", "\"nodes\": [100000, 100000]", MPM_ETOOBIG,
                   "grid.nodes: 10000000000 nodes, more than the limit"))
        return;
    if (expect_bad("\"radius\": 0.1", "\"radius\": 0.1}, \"ppc\": 8, \"x\": {", MPM_EINVAL,
                   "bodies[0].x: unknown field"))
        return;
    if (expect_bad("\"spacing\": [0.1, 0.1], \"nodes\": [11, 11]",
                   "\"spacing\": [1e-4, 1e-4], \"nodes\": [4000, 4000]", MPM_ETOOBIG,
                   "bodies[0]: about"))
        return;
    if (expect_bad("\"density\": 1", "\"density\": -1", I,
                   "materials[0].density: must be > 0 (got -1)"))
        return;
    if (expect_bad("\"poissonRatio\": 0.2", "\"poissonRatio\": 0.5", I,
                   "materials[0].poissonRatio: must be in (-1, 0.5)"))
        return;
    if (expect_bad("\"youngsModulus\": 1, ", "", I, "materials[0].youngsModulus: missing")) return;
    if (expect_bad("\"endTime\": 1", "\"endTime\": 0", I, "endTime: must be > 0")) return;
    if (expect_bad("\"endTime\": 1", "\"steps\": 0", I, "steps: must be 1..")) return;
    if (expect_bad(", \"endTime\": 1", "", I, "endTime: missing (a case needs endTime or steps)"))
        return;
    /* dt is the solver's to judge (the codec no longer checks it twice) */
    if (expect_bad("\"endTime\": 1", "\"endTime\": 1, \"dt\": -1", I,
                   "dt: must be finite and >= 0 (0: automatic) (got -1)"))
        return;
    if (expect_bad("\"endTime\": 1", "\"endTime\": 1, \"threads\": 1000", I,
                   "threads: must be 0.."))
        return;
    if (expect_bad("\"endTime\": 1", "\"endTime\": 1, \"gravity\": [0, -9.8, 0]", I,
                   "gravity: expected 2 values (one per axis), got 3"))
        return;
    if (expect_bad("\"endTime\": 1", "\"endTime\": 1, \"boundary\": {\"zLo\": 7}", I,
                   "boundary.zLo: the grid has no axis 2 (dim 2)"))
        return;
    if (expect_bad("\"endTime\": 1", "\"endTime\": 1, \"boundary\": {\"xHi\": 8}", I,
                   "boundary.xHi: mask 8 has bits other than"))
        return;
    if (expect_bad(
            "\"endTime\": 1",
            "\"endTime\": 1, \"boundary\": {\"nodes\": [{\"ijk\": [0, 0]}, {\"ijk\": [3, 11]}]}", I,
            "boundary.nodes[1].ijk[1]: 11 is outside the grid (nodes[1] = 11)"))
        return;
    if (expect_bad("\"endTime\": 1", "\"endTime\": 1, \"boundary\": {\"nodes\": [{\"ijk\": [0]}]}",
                   I, "boundary.nodes[0].ijk: expected 2 indices"))
        return;
    if (expect_bad(
            "\"endTime\": 1",
            "\"endTime\": 1, \"tractions\": [{\"lo\": [0, 0], \"hi\": [1, 1], \"normal\": 2, \"value\": [1, 0]}]",
            I, "tractions[0].normal: must be an axis below dim 2 (got 2)"))
        return;
    if (expect_bad("\"endTime\": 1",
                   "\"endTime\": 1, \"tractions\": [{\"lo\": [0, 0], \"hi\": [1, 1]}]", I,
                   "tractions[0].value: missing"))
        return;
    if (expect_bad("\"materials\": [{", "\"materials\": [], \"x\": [{", I, "x: unknown field"))
        return;
    {
        const char *nomat =
            "{\"grid\": {\"dim\": 1, \"spacing\": [1], \"nodes\": [2]}, \"bodies\": [{\"points\": "
            "{\"x\": [0.5], \"volume\": [1]}}], \"endTime\": 1}";
        CHECK(load_text(nomat, err) == I);
        CHECKF(strstr(err, "materials: at least one material is required"), "%s", err);
    }
    /* explicit points: sizes per point */
    static const struct {
        const char *to, *want;
    } pts[] = {
        {"\"x\": [0.5, 0.5, 0.7], \"volume\": [0.01, 0.01]",
         "bodies[0].points.x: expected 4 values (per point), got 3"},
        {"\"x\": [0.5, 0.5], \"volume\": []",
         "bodies[0].points.volume: at least one point is required"},
        {"\"x\": [0.5, 0.5], \"volume\": [0]", "bodies[0].points.volume[0]: must be > 0 (got 0)"},
        {"\"x\": [0.5, 0.5], \"volume\": [0.01], \"mass\": [1, 2]",
         "bodies[0].points.mass: expected 1 values (per point, or none), got 2"},
        {"\"x\": [0.5, 0.5], \"volume\": [0.01], \"v\": [1]",
         "bodies[0].points.v: expected 2 values"},
        {"\"x\": [0.5, 0.5], \"volume\": [0.01], \"stress\": [1, 2, 3]",
         "bodies[0].points.stress: expected 6 values"},
        {"\"x\": [0.5, 0.5], \"volume\": [0.01], \"halfLength\": [0.05, -0.05]",
         "bodies[0].points.halfLength[1]: must be > 0"},
        {"\"x\": [0.5, \"Infinity\"], \"volume\": [0.01]",
         "bodies[0].points.x[1]: must be a finite number"},
    };
    for (size_t i = 0; i < sizeof pts / sizeof pts[0]; i++) {
        char json[512];
        snprintf(json, sizeof json,
                 "{\"grid\": {\"dim\": 2, \"spacing\": [0.1, 0.1], \"nodes\": [11, 11]},"
                 " \"materials\": [{\"youngsModulus\": 1, \"density\": 1}],"
                 " \"bodies\": [{\"points\": {%s}}], \"endTime\": 1}",
                 pts[i].to);
        int rc = load_text(json, err);
        CHECKF(rc == I && strstr(err, pts[i].want), "rc %d: %s (want %s)", rc, err, pts[i].want);
        TLOG("%s", err);
    }
}

/* Damaged protobuf bytes: errors, never crashes (ASan watches). */
/* The schema's defaults (BSPLINE2 with MUSL since 0.4.0; GIMP with MUSL before), made explicit by
 * mpp_case_pin_defaults(), and the solver's own checks reported with
 * lowerCamelCase paths like the codec's. */
TEST(codec_defaults)
{
    char err[T_ERRLEN], *json = NULL;
    Mpmd__Case *pb = NULL, *back = NULL;
    mpp_case *sc = NULL;
    uint8_t *buf = NULL;
    size_t n = 0;
    CHECKF(td_case_load(td_good2d, strlen(td_good2d), &sc, err, sizeof err) == 0, "%s", err);
    CHECKF(sc->c.method == MPM_METHOD_BSPLINE2 && sc->c.update == MPM_MUSL,
           "a case without method/update: method %d, update %d (want BSPLINE2, MUSL)",
           (int)sc->c.method, (int)sc->c.update);
    mpp_case_destroy(&sc);

    /* absent stays absent in JSON until pinned; pinned, the bytes say it */
    CHECK(td_case_from_json(td_good2d, strlen(td_good2d), &pb, err, sizeof err) == 0);
    CHECK(case_to_json(pb, 0, &json, err) == 0);
    CHECKF(!strstr(json, "\"method\"") && !strstr(json, "\"update\""), "unpinned: %s", json);
    free(json);
    json = NULL;
    mpp_case_pin_defaults(pb);
    CHECK(mpp_case_pack(pb, &buf, &n) == 0);
    mpp_case_pb_free(&pb);
    CHECK(td_case_unpack(buf, n, 0, &back, err, sizeof err) == 0);
    free(buf);
    CHECK(case_to_json(back, 0, &json, err) == 0);
    mpp_case_pb_free(&back);
    TLOG("pinned: %.90s...", json);
    CHECKF(strstr(json, "\"method\":\"BSPLINE2\",\"update\":\"MUSL\""), "pinned: %s", json);
    free(json);
    json = NULL;
    {
        char *mpm =
            td_patch("\"endTime\": 1", "\"endTime\": 1, \"method\": \"MPM\", \"update\": \"USL\"");
        CHECK(mpm);
        int rc = td_case_from_json(mpm, strlen(mpm), &pb, err, sizeof err);
        free(mpm);
        CHECK(rc == 0);
        mpp_case_pin_defaults(pb);
        rc = case_to_json(pb, 0, &json, err);
        mpp_case_pb_free(&pb);
        CHECK(rc == 0);
        CHECKF(strstr(json, "\"method\":\"MPM\",\"update\":\"USL\""), "explicit MPM USL pinned: %s",
               json);
        free(json);
    }
    /* a solver check (GMPM half-width above h; GIMP named: not the default) names the field as
     * JSON does */
    {
        const char *wide =
            "{\"grid\": {\"dim\": 1, \"spacing\": [0.1], \"nodes\": [11]}, \"method\": \"GIMP\","
            " \"materials\": [{\"youngsModulus\": 1, \"density\": 1}],"
            " \"bodies\": [{\"points\": {\"x\": [0.45, 0.55], \"volume\": [0.1, 0.1],"
            " \"halfLength\": [0.05, 0.2]}}], \"steps\": 1}";
        int rc = load_text(wide, err);
        TLOG("half-width above h: %s", err);
        const char *colon = strstr(err, ": ");
        CHECKF(rc == MPM_EINVAL && !strncmp(err, "bodies[0].", 10) && colon && colon - err >= 13 &&
                   !strncmp(colon - 13, "halfLength[1]", 13),
               "rc %d: %s (want the path bodies[0]...halfLength[1] first)", rc, err);
    }
}

/* int-typed views of the name table's functions, for one loop below */
static const char *names_method(int v)
{
    return mpm_method_name((mpm_method)v);
}
static const char *keys_method(int v)
{
    return mpm_method_key((mpm_method)v);
}
static const char *names_update(int v)
{
    return mpm_update_name((mpm_update)v);
}
static const char *keys_update(int v)
{
    return mpm_update_key((mpm_update)v);
}
static const char *names_transfer(int v)
{
    return mpm_transfer_name((mpm_transfer)v);
}
static const char *keys_transfer(int v)
{
    return mpm_transfer_key((mpm_transfer)v);
}

/* The solver's one name table (mpm_names.c) against the schema's enums:
 * every method, update and transfer has the protocol's name for its value,
 * its key is that name in lower case, and parsing takes both spellings
 * back to the value; a value outside the enum is "?" and an unknown name
 * -1. */
TEST(codec_names_match_proto)
{
    static const struct {
        const ProtobufCEnumDescriptor *d;
        const char *(*name)(int), *(*key)(int);
        int (*parse)(const char *);
        int n;
    } t[] = {
        {&mpmd__case__method__descriptor, names_method, keys_method, mpm_method_parse,
         MPM_N_METHODS},
        {&mpmd__case__update__descriptor, names_update, keys_update, mpm_update_parse,
         MPM_N_UPDATES},
        {&mpmd__case__transfer__descriptor, names_transfer, keys_transfer, mpm_transfer_parse,
         MPM_N_TRANSFERS},
    };
    for (size_t i = 0; i < sizeof t / sizeof t[0]; i++) {
        CHECK((int)t[i].d->n_values == t[i].n);
        for (int v = 0; v < t[i].n; v++) {
            const ProtobufCEnumValue *ev = protobuf_c_enum_descriptor_get_value(t[i].d, v);
            CHECK(ev != NULL);
            if (!ev) continue;
            CHECKF(!strcmp(ev->name, t[i].name(v)), "%s: %s vs %s", t[i].d->name, ev->name,
                   t[i].name(v));
            char low[32];
            size_t k = 0;
            for (; ev->name[k] && k + 1 < sizeof low; k++)
                low[k] = (char)(ev->name[k] >= 'A' && ev->name[k] <= 'Z' ? ev->name[k] + 32
                                                                         : ev->name[k]);
            low[k] = 0;
            CHECK(!strcmp(low, t[i].key(v)));
            CHECK(t[i].parse(ev->name) == v && t[i].parse(low) == v);
        }
        CHECK(!strcmp(t[i].name(t[i].n), "?"));
        CHECK(t[i].parse("no such name") == -1 && t[i].parse(NULL) == -1);
    }
}
