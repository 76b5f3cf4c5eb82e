/*
 * t_codec.c - tests of the wire schema and the protocol library: the
 * generic JSON <-> protobuf converter (mpp_json) and the case conversion
 * (mpp_case), the envelopes (mpp_request, mpp_reply, mpp_stream), the
 * vocabulary (mpp.h) and the endpoint rules (mpp_endpoint): every example case
 * loads into the expected mpm_case, cases survive JSON -> protobuf -> bytes
 * -> JSON unchanged, bad input is rejected with the JSON path of the
 * offending field, damaged bytes give errors (not crashes), and the
 * Request / Reply / StreamMsg helpers encode what they should (the client
 * decoders are tested in t_codec_decode.c, the Python interoperability in
 * t_codec_python.c).
 * Example files are read relative to the repository root.
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
#include "t_daemon.h"

/* mpp_case_from_pb under the default particle limit, the error as text. */
static int from_pb(const Mpmd__Case *pb, mpp_case **out, char *err)
{
    mpm_error e;
    return t_errtext(mpp_case_from_pb(pb, 0, out, &e), &e, err);
}

static int case_to_json(const Mpmd__Case *pb, unsigned flags, char **json, char *err)
{
    mpm_error e;
    return t_errtext(mpp_case_to_json(pb, flags, json, &e), &e, err);
}

static int req_decode(const void *buf, size_t n, size_t max, mpp_request *rq, char *err)
{
    mpm_error e;
    return t_errtext(mpp_request_decode(buf, n, max, rq, &e), &e, err);
}

/* Loads proto/examples/<name>.json into an mpp_case (NULL on failure, with
 * the reason printed). */
static mpp_case *load_example(const char *name)
{
    char path[256], err[T_ERRLEN];
    size_t len = 0;
    mpp_case *sc = NULL;
    snprintf(path, sizeof path, "proto/examples/%s.json", name);
    char *text = td_slurp(path, &len);
    if (!text) {
        TLOG("cannot read %s (run from the repository root)", path);
        return NULL;
    }
    int rc = td_case_load(text, len, &sc, err, sizeof err);
    if (rc) TLOG("%s: rc %d: %s", path, rc, err);
    free(text);
    return sc;
}

/* Builds the solver from a converted case and returns its particle count
 * (0 with the reason printed if the solver refuses it). */
static size_t sim_particles(const mpp_case *sc)
{
    mpm_error err;
    mpm_sim *sim = mpm_sim_new(&sc->c, NULL, &err); /* checked again, from scratch */
    size_t n;
    if (!sim) {
        TLOG("mpm_sim_new: %s", TERR(&err));
        return 0;
    }
    n = mpm_sim_particles(sim);
    mpm_sim_destroy(&sim);
    if (n != sc->info.particles) { /* the codec's check counted them */
        TLOG("the codec's check counted %zu particles, the solver made %zu", sc->info.particles, n);
        return 0;
    }
    return n;
}

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

/* Number of sub-cell centres of a grid inside a disk, by the fill rule the
 * solver documents: x = origin + (c + (s + 0.5)/ppc) h, kept if inside. */
static int disk_count(const mpm_case *c, const mpm_body_desc *b)
{
    int n = 0, ppc = b->ppc;
    for (int i = 0; i < (c->grid.nodes[0] - 1) * ppc; i++)
        for (int j = 0; j < (c->grid.nodes[1] - 1) * ppc; j++) {
            double x = c->grid.origin[0] + (i / ppc + (i % ppc + 0.5) / ppc) * c->grid.h[0];
            double y = c->grid.origin[1] + (j / ppc + (j % ppc + 0.5) / ppc) * c->grid.h[1];
            double dx = x - b->center[0], dy = y - b->center[1];
            n += dx * dx + dy * dy < b->radius * b->radius;
        }
    return n;
}

TEST(codec_example_point1d)
{
    mpp_case *sc = load_example("point1d");
    CHECK(sc);
    const mpm_case *c = &sc->c;
    CHECK(!strcmp(sc->name, "point1d"));
    CHECK(c->grid.dim == 1 && c->grid.nodes[0] == 2);
    CHECK_NEAR(c->grid.h[0], 1.0, 0);
    CHECK_NEAR(c->grid.origin[0], 0.0, 0);
    CHECK(c->method == MPM_METHOD_MPM && c->update == MPM_USF);
    CHECK_NEAR(c->dt, 0.001, 0);
    CHECK(c->n_materials == 1);
    CHECK_NEAR(c->materials[0].youngs_modulus, 4 * M_PI * M_PI, 1e-13);
    CHECK_NEAR(c->materials[0].density, 1.0, 0);
    CHECK(c->n_bodies == 1 && c->bodies[0].n_points == 1);
    CHECK_NEAR(c->bodies[0].x[0], 0.5, 0);
    CHECK_NEAR(c->bodies[0].volume[0], 1.0, 0);
    CHECK(!c->bodies[0].mass && !c->bodies[0].v && !c->bodies[0].stress &&
          !c->bodies[0].half_length);
    CHECK_NEAR(c->bodies[0].velocity[0], 0.1, 0);
    CHECK(c->bc.face_mask[0] == 1 && c->bc.face_mask[1] == 0 && c->bc.n_nodes == 0);
    CHECK(sc->has_end_time);
    CHECK_NEAR(sc->end_time, 3.0, 0);
    CHECK(sc->energy_every == 10 && sc->snapshot_every == 0 && sc->snapshot_fields == MPP_SNAP_ALL);
    CHECK(sc->explicit_points == 1 && sc->info.particles == 1 && sc->info.nodes == 2);
    CHECK(sim_particles(sc) == 1);
    mpp_case_destroy(&sc);
    CHECK(sc == NULL);
}

/* The 1D bars: n points at cell centres, v = 0.1 sin(pi x / 2). */
static void check_bar(const char *name, int n, mpm_method method)
{
    mpp_case *sc = load_example(name);
    CHECK(sc);
    const mpm_case *c = &sc->c;
    const mpm_body_desc *b = &c->bodies[0];
    double h = 1.0 / n;
    CHECK(c->grid.dim == 1 && c->grid.nodes[0] == n + 1);
    CHECK_NEAR(c->grid.h[0], h, 1e-16);
    CHECK(c->method == method && c->update == MPM_USF);
    CHECK_NEAR(c->dt, 0.001, 0);
    CHECK_NEAR(c->materials[0].youngs_modulus, 10, 0);
    CHECK_NEAR(c->materials[0].density, 1, 0);
    CHECK(c->n_bodies == 1 && b->n_points == (size_t)n && b->v && !b->mass);
    for (int i = 0; i < n; i++) {
        double x = (i + 0.5) * h;
        CHECK_NEAR(b->x[i], x, 1e-15);
        CHECK_NEAR(b->volume[i], h, 1e-16);
        CHECK_NEAR(b->v[i], 0.1 * sin(M_PI * x / 2), 1e-16);
    }
    CHECK(c->bc.face_mask[0] == 1 && c->bc.face_mask[1] == 0);
    CHECK(sim_particles(sc) == (size_t)n);
    mpp_case_destroy(&sc);
}

TEST(codec_example_bar1d_mpm)
{
    check_bar("bar1d_mpm", 7, MPM_METHOD_MPM);
}

TEST(codec_example_bar1d_gimp)
{
    check_bar("bar1d_gimp", 13, MPM_METHOD_GIMP);
}

/* the bar with quadratic B-splines: 16 cells of 2 points, 2 empty cells
 * beyond the free end */
TEST(codec_example_bar1d_bspline2)
{
    mpp_case *sc = load_example("bar1d_bspline2");
    CHECK(sc);
    const mpm_case *c = &sc->c;
    CHECK(c->method == MPM_METHOD_BSPLINE2 && c->update == MPM_USF);
    CHECK(c->grid.dim == 1 && c->grid.nodes[0] == 19 && c->bc.face_mask[0] == 1);
    CHECK(sim_particles(sc) == 32);
    mpp_case_destroy(&sc);
}

static void check_disks(const char *name, int nodes, double h, int per_disk)
{
    mpp_case *sc = load_example(name);
    CHECK(sc);
    const mpm_case *c = &sc->c;
    CHECK(c->grid.dim == 2 && c->grid.nodes[0] == nodes && c->grid.nodes[1] == nodes);
    CHECK_NEAR(c->grid.h[0], h, 0);
    CHECK_NEAR(c->grid.h[1], h, 0);
    CHECK(c->method == MPM_METHOD_GIMP && c->update == MPM_USF);
    CHECK(c->dt == 0.001); /* the paper's dt */
    CHECK_NEAR(c->materials[0].youngs_modulus, 1, 0);
    CHECK_NEAR(c->materials[0].poisson_ratio, 0.2, 0);
    CHECK(c->n_bodies == 2);
    for (int k = 0; k < 2; k++) {
        const mpm_body_desc *b = &c->bodies[k];
        double ctr = k ? 0.75 : 0.25, sgn = k ? -1 : 1;
        CHECK(b->n_points == 0 && b->shape == MPM_SHAPE_SPHERE && b->ppc == 2 && b->material == 0);
        CHECK_NEAR(b->center[0], ctr, 0);
        CHECK_NEAR(b->center[1], ctr, 0);
        CHECK_NEAR(b->radius, 0.14, 0);
        CHECK_NEAR(b->velocity[0], sgn * 0.0707106781186548, 1e-15);
        CHECK_NEAR(hypot(b->velocity[0], b->velocity[1]), 0.1, 1e-15);
        int cnt = disk_count(c, b);
        TLOG("%s: disk %d has %d particles (h = %g, ppc 2)", name, k, cnt, h);
        CHECK(cnt == per_disk);
    }
    CHECK(sc->has_end_time);
    CHECK_NEAR(sc->end_time, 4.0, 0);
    CHECK(sc->snapshot_every == 100);
    CHECK(sc->snapshot_fields == (MPP_SNAP_X | MPP_SNAP_V | MPP_SNAP_PRESSURE));
    CHECK(sc->explicit_points == 0 && sc->info.particles == (size_t)(2 * per_disk));
    CHECK(sc->info.nodes == (size_t)nodes * (size_t)nodes);
    size_t np = sim_particles(sc);
    TLOG("%s: the solver fills %zu particles", name, np);
    CHECK(np == (size_t)(2 * per_disk) && np == sc->info.particles);
    mpp_case_destroy(&sc);
}

TEST(codec_example_disks2d)
{
    check_disks("disks2d_coarse", 11, 0.1, 24);
    if (t_failed()) return;
    check_disks("disks2d_fine", 41, 0.025, 392);
}

/* The spinning disk with APIC: the transfer's JSON spelling, explicit
 * points turning rigidly about (0.5, 0.5). */
TEST(codec_example_disk2d_apic)
{
    mpp_case *sc = load_example("disk2d_apic");
    CHECK(sc);
    const mpm_case *c = &sc->c;
    const mpm_body_desc *b = &c->bodies[0];
    CHECK(c->transfer == MPM_TRANSFER_APIC && c->pic_fraction == 0);
    CHECK(c->method == MPM_METHOD_GIMP && c->update == MPM_MUSL);
    CHECK(b->n_points == 208 && b->v && b->x);
    for (size_t i = 0; i < b->n_points; i++) {
        double rx = b->x[2 * i] - 0.5, ry = b->x[2 * i + 1] - 0.5;
        CHECK_NEAR(b->v[2 * i] * rx + b->v[2 * i + 1] * ry, 0, 1e-8); /* tangential */
    }
    CHECK(sim_particles(sc) == 208);
    mpp_case_destroy(&sc);
    /* absent: FLIP */
    sc = load_example("disks2d_coarse");
    CHECK(sc);
    CHECK(sc->c.transfer == MPM_TRANSFER_FLIP);
    mpp_case_destroy(&sc);
}

TEST(codec_example_cube3d)
{
    mpp_case *sc = load_example("cube3d");
    CHECK(sc);
    const mpm_case *c = &sc->c;
    const mpm_body_desc *b = &c->bodies[0];
    CHECK(c->grid.dim == 3);
    CHECK(c->grid.nodes[0] == 11 && c->grid.nodes[1] == 3 && c->grid.nodes[2] == 3);
    CHECK(b->n_points == 320 && b->v && b->x);
    CHECK_NEAR(c->materials[0].poisson_ratio, 0, 0);
    unsigned want[6] = {7, 0, 2, 2, 4, 4};
    for (int f = 0; f < 6; f++) CHECK(c->bc.face_mask[f] == want[f]);
    double vol = 0, xmax = 0;
    for (size_t i = 0; i < b->n_points; i++) {
        vol += b->volume[i];
        if (b->x[3 * i] > xmax) xmax = b->x[3 * i];
        CHECK_NEAR(b->v[3 * i], 0.1 * sin(M_PI * b->x[3 * i] / 2), 1e-15);
        CHECK(b->v[3 * i + 1] == 0 && b->v[3 * i + 2] == 0);
    }
    CHECK_NEAR(vol, 1.0 * 0.2 * 0.2, 1e-12);
    CHECK_NEAR(xmax, 0.975, 1e-15);
    CHECK(sim_particles(sc) == 320);
    mpp_case_destroy(&sc);
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

/* The CPDI example (a soft bar hanging under its suddenly applied weight,
 * rho g H / E = 1/3, about one and a half periods) decodes to a CPDI case
 * and runs to its end time without failing.  (Run on to t = 1.64, when the
 * undamped bar is back near its start with K + S ~ 0, the divergence guard
 * trips on a +0.4 % energy drift: K + S > 2 (E0 - P), a bound meant for a
 * blow-up; GIMP USL loses 20 % of the energy by then and passes.) */
TEST(codec_cpdi_example_runs)
{
    mpp_case *sc = load_example("hangbar2d_cpdi");
    CHECK(sc);
    CHECK(sc->c.method == MPM_METHOD_CPDI && sc->c.update == MPM_USL && sc->has_end_time);
    mpm_error err;
    mpm_sim *s = mpm_sim_new(&sc->c, NULL, &err);
    CHECKF(s, "%s", TERR(&err));
    int rc = 0;
    while (!rc && mpm_sim_time(s) < sc->end_time) rc = mpm_sim_step(s);
    if (!rc) rc = mpm_sim_check(s);
    TLOG("hangbar2d_cpdi: %zu points, %ld steps to t = %.3f: %s", mpm_sim_particles(s),
         mpm_sim_steps(s), mpm_sim_time(s), rc ? TERR(mpm_sim_error(s)) : "ok");
    mpm_sim_destroy(&s);
    mpp_case_destroy(&sc);
    CHECK(rc == 0);
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
