/*
 * mpm_error.h - the one error value of mpmd: {code, field, message}.
 *
 * Every layer (the solver, the protocol library, the store, the daemon and
 * mpmctl) reports a failure the same way: the function returns a negative
 * MPM_E* code and, when the caller passed an mpm_error, fills it in.  The
 * field is a structured path of schema names (snake_case, as in
 * proto/mpmd.proto) with optional indices, e.g. bodies[0] . points .
 * half_length[3]; it is rendered as text once, at the edge, either in the
 * proto spelling ("bodies[0].points.half_length[3]") or in the JSON
 * mapping's lowerCamelCase ("bodies[0].points.halfLength[3]").  Nothing
 * parses an error text back.
 *
 * The codes are shared by every layer; the wire's Error.Code is chosen from
 * them in one place (the protocol library's mpp_error_wire_code()).
 *
 * This header is plain C with no dependency: the solver library includes it
 * and so can everything above it.
 */
#ifndef MPM_ERROR_H
#define MPM_ERROR_H

#include <stddef.h>

/* Error codes (negative; 0 is success).  mpm_strerror() names them. */
enum {
    MPM_OK = 0,
    MPM_EINVAL = -1,     /* an input field is invalid (the field names it) */
    MPM_ENOMEM = -2,     /* allocation failed */
    MPM_ELEFTGRID = -3,  /* solver: a particle left the grid */
    MPM_EDIVERGED = -4,  /* solver: NaN, Inf or an energy blow-up */
    MPM_ECANCELLED = -5, /* solver: cancelled */
    MPM_ECFL = -6,       /* a given dt above the CFL limit */
    MPM_ESTATE = -7,     /* an operation not allowed in this state */
    MPM_ETOOBIG = -8,    /* above a size or count limit (the field names it) */
    MPM_ESYNTAX = -9,    /* bytes or text that do not decode */
    MPM_EVERSION = -10,  /* another schema version */
    MPM_ENOTFOUND = -11, /* no such run, job or snapshot */
    MPM_ECONFLICT = -12, /* the object is in the wrong state (already ended) */
    MPM_EFULL = -13,     /* a queue is full */
    MPM_EUNAVAIL = -14,  /* shutting down / not accepting */
    MPM_EIO = -15,       /* file system, database or socket failure */
    MPM_ELOCKED = -16,   /* the database is in use by another mpmd */
    MPM_ESCHEMA = -17,   /* not an mpmd database, or a newer schema */
    MPM_EREQUEST = -18,  /* a request that lacks a body or a required id */
    MPM_EINTERNAL = -19, /* a bug or an impossible state */
    MPM_EFORBIDDEN = -20 /* the requester may not do this (not the owner) */
};
#define MPM_E_LAST MPM_EFORBIDDEN

#define MPM_PATH_MAX 8        /* path elements */
#define MPM_PATH_NAME_MAX 32  /* bytes of one element's name, with NUL */
#define MPM_ERROR_MSG_MAX 400 /* bytes of the message, with NUL */

/* One element of a field path: a schema name (snake_case) and an index
 * (< 0: none), e.g. {"bodies", 0}, {"points", -1}, {"half_length", 3}. */
typedef struct {
    char name[MPM_PATH_NAME_MAX];
    long index;
} mpm_path_elem;

/* The error value.  All-zero is "no error".  It owns no memory, so it can
 * be copied, returned and kept in any struct. */
typedef struct {
    int code;  /* MPM_E*, 0 = none */
    int depth; /* path elements in use */
    mpm_path_elem path[MPM_PATH_MAX];
    char message[MPM_ERROR_MSG_MAX]; /* the text, without the field */
} mpm_error;

/* Spellings for mpm_error_field(). */
typedef enum {
    MPM_FIELD_PROTO = 0, /* snake_case as in the .proto: half_length */
    MPM_FIELD_JSON = 1   /* lowerCamelCase as in the JSON mapping: halfLength */
} mpm_field_style;

/* Sets *e (when e is not NULL) to code with a printf-style message and the
 * field given as a path string in proto spelling ("bodies[0].points.x[3]",
 * "" or NULL: none); returns code, so that `return mpm_fail(...)` works.
 * An element beyond MPM_PATH_MAX or a name too long is cut. */
int mpm_fail(mpm_error *e, int code, const char *field, const char *fmt, ...)
    __attribute__((format(printf, 4, 5)));

/* Clears *e to "no error" (e may be NULL). */
void mpm_error_clear(mpm_error *e);

/* Appends / prepends one path element ("name" with index, < 0 for none):
 * a caller that checks a sub-object lets the callee fill the inner path,
 * then prefixes its own (e.g. the codec adds "bodies[2]" in front of what
 * a body check found).  Silently cut beyond MPM_PATH_MAX. */
void mpm_error_push(mpm_error *e, const char *name, long index);
void mpm_error_prefix(mpm_error *e, const char *name, long index);

/* Renders the field path into buf (n bytes, always NUL-terminated; "" when
 * there is none) in the given spelling; returns buf. */
char *mpm_error_field(const mpm_error *e, mpm_field_style style, char *buf, size_t n);

/* Renders "field: message" (or just the message when there is no field)
 * into buf; returns buf.  For logs and for a human on the command line. */
char *mpm_error_text(const mpm_error *e, mpm_field_style style, char *buf, size_t n);

/* snake_case -> lowerCamelCase of one name into out (n bytes). */
void mpm_camel_case(const char *snake, char *out, size_t n);

/* A short name of a code: "invalid input", "out of memory", ... */
const char *mpm_strerror(int code);

#endif
