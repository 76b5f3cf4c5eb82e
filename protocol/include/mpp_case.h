/*
 * mpp_case.h - a simulation case from the wire to the solver: JSON text or
 * protobuf bytes -> Mpmd__Case (the generated message, opaque here) ->
 * mpp_case, a checked, self-contained mpm_case ready for mpm_sim_new(),
 * with the run control and output requests beside it and what the solver's
 * check found (mpm_case_info: the particle and node counts, ...), so
 * nobody checks or counts again.
 *
 * The conversion checks only what the schema cannot express (dimensions,
 * array lengths, indices, enum values it maps, value ranges of the run
 * control, size limits before anything big is copied); the physics (dt,
 * CFL, method, update, materials, geometry) is the solver's check, run
 * once here.  Errors are mpm_error values: MPM_EINVAL / MPM_ECFL (the field
 * names what is wrong), MPM_ETOOBIG (a limit), MPM_ESYNTAX (not JSON or
 * not a Case), MPM_ENOMEM.
 */
#ifndef MPP_CASE_H
#define MPP_CASE_H

#include <stddef.h>
#include <stdint.h>

#include "mpm.h"
#include "mpp.h"

/* The generated case message; opaque outside protocol/. */
typedef struct Mpmd__Case Mpmd__Case;

/* Limits applied while converting a case (a case above them is refused
 * with MPM_ETOOBIG before anything big is copied).  The particle limit is
 * the caller's (mpp_case_from_pb's max_particles). */
#define MPP_CASE_MAX_NODES 20000000u      /* grid nodes */
#define MPP_CASE_MAX_ITEMS 100000u        /* materials, bodies, tractions each */
#define MPP_CASE_MAX_NODE_FIXES 10000000u /* boundary.nodes, prescribed nodes */
#define MPP_CASE_MAX_TABLE 1000000u       /* points of all TimeFunction tables */
#define MPP_CASE_MAX_STEPS 1000000000000LL
/* Default largest message accepted by the unpack functions (max = 0). */
#define MPP_MSG_MAX ((size_t)512 << 20)
/* Memory an unpack may take for a message of n bytes: MPP_UNPACK_INFLATE * n
 * + MPP_UNPACK_FLOOR (every unpack of the library; more fails with
 * MPM_ETOOBIG).  Honest messages take at most a few times their size
 * (packed arrays 1x, a boundary node fix about 7x); crafted ones (empty
 * repeated sub-messages) would take about 45x. */
#define MPP_UNPACK_INFLATE 8
#define MPP_UNPACK_FLOOR (1 << 20)
/* The budget of a message of len bytes (saturating). */
size_t mpp_unpack_budget(size_t len);
/* Longest case name accepted (bytes); longer is INVALID_CASE on `name`. */
#define MPP_NAME_MAX 256

/* Snapshot field bits (mpp_case.snapshot_fields). */
enum {
    MPP_SNAP_X = 1,
    MPP_SNAP_V = 2,
    MPP_SNAP_STRESS = 4,
    MPP_SNAP_PRESSURE = 8,
    MPP_SNAP_VOLUME = 16,
    /* only in runs whose particles carry them (mpm_sim_has_field()) */
    MPP_SNAP_PLASTIC_STRAIN = 32,
    MPP_SNAP_DEFORMATION_GRADIENT = 64,
    MPP_SNAP_YIELDED = 128,
    MPP_SNAP_ALL = 255
};

/* A converted, checked case.  `c` points only into this struct's own
 * arrays, so it stays valid until mpp_case_destroy() whatever happens to
 * the message it came from. */
typedef struct mpp_case {
    mpm_case c;         /* the solver case (passed mpm_case_check; its
                           max_particles is the limit it was checked under) */
    mpm_case_info info; /* what the check found: particles, nodes, ...;
                           give it to mpm_sim_new() to build unchecked */
    char *name;         /* Case.name, "" when absent */
    int has_end_time;   /* 1: run until end_time; 0: run `steps` steps */
    double end_time;
    long long steps;
    unsigned energy_every;           /* Output.energy_every (0: only the final sample) */
    unsigned snapshot_every;         /* Output.snapshot_every (0: none) */
    unsigned snapshot_fields;        /* MPP_SNAP_* bits; MPP_SNAP_ALL when none listed */
    int record_snapshots;            /* Output.record_snapshots */
    int has_checkpoint;              /* Case.checkpoint present (0: the server's default) */
    unsigned checkpoint_every_steps; /* Checkpoint.every_steps (0: not by steps) */
    double checkpoint_every_wall_s;  /* Checkpoint.every_wall_s (0: not by time) */
    size_t explicit_points;          /* particles given as explicit points */

    /* Storage behind c (owned). */
    mpm_material_desc *materials;
    mpm_body_desc *bodies;
    double **point_blocks; /* per body: its explicit arrays, or NULL */
    mpm_traction_desc *tractions;
    int *node_ijk;
    unsigned *node_mask;
    mpm_friction_desc *friction;     /* boundary.friction */
    mpm_prescribed_desc *prescribed; /* prescribed */
    int *presc_ijk;                  /* their node sets, 3 ints per node */
    mpm_timefn *timefns;             /* time functions of tractions and prescribed */
    double *tf_data;                 /* the TABLE points of those */
} mpp_case;

/* JSON text -> case message (schema checks only: names, types, enums).
 * *out is NULL on error; free it with mpp_case_pb_free(). */
int mpp_case_from_json(const char *json, size_t len, Mpmd__Case **out, mpm_error *err);

/* Packed bytes -> case message; max is the largest len accepted (0:
 * MPP_MSG_MAX).  Garbage or truncated bytes give MPM_ESYNTAX. */
int mpp_case_unpack(const void *buf, size_t len, size_t max, Mpmd__Case **out, mpm_error *err);

/* Case message -> packed bytes in a malloc'd *buf of *len bytes (*buf is
 * never NULL on success, even for 0 bytes).  Returns 0 or MPM_ENOMEM. */
int mpp_case_pack(const Mpmd__Case *pb, uint8_t **buf, size_t *len);

/* Case message -> JSON text (flags: 0 or MPP_JSON_PRETTY) in a malloc'd
 * string. */
int mpp_case_to_json(const Mpmd__Case *pb, unsigned flags, char **json, mpm_error *err);

/* Frees a case message and nulls the pointer (NULL is fine). */
void mpp_case_pb_free(Mpmd__Case **pb);

/* Marks Case.method and Case.update present (with their current values,
 * the schema's defaults when they were absent), so the packed case says
 * which method and update it means to any peer, whatever its defaults. */
void mpp_case_pin_defaults(Mpmd__Case *pb);

/* Case message -> mpp_case: converts and checks (see above), refusing a
 * case of more than max_particles particles (0: MPP_DEFAULT_MAX_PARTICLES)
 * with MPM_ETOOBIG: the limit of the solver's counting pass (which stops
 * there) and of the conversion's own guards before its copies.  *out is
 * NULL on error. */
int mpp_case_from_pb(const Mpmd__Case *pb, size_t max_particles, mpp_case **out, mpm_error *err);

/* JSON text -> mpp_case in one call (mpp_case_from_json + _from_pb). */
int mpp_case_load(const char *json, size_t len, size_t max_particles, mpp_case **out,
                  mpm_error *err);

/* Frees an mpp_case and nulls the pointer (NULL is fine). */
void mpp_case_destroy(mpp_case **mc);

#endif
