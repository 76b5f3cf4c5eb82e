/*
 * mpp_json.h - the JSON mapping of the protocol library: generic conversion
 * between JSON text and protobuf-c messages,
 * following the protobuf JSON mapping, driven only by the message
 * descriptors (so a field added to a .proto needs no C change here).
 *
 * JSON -> protobuf: field names in lowerCamelCase or as in the .proto;
 * enums as value names (or numbers); 64-bit integers as numbers or decimal
 * strings; floating point as numbers or the strings "NaN", "Infinity",
 * "-Infinity" (or a numeric string); bytes as base64; repeated fields as
 * arrays; map fields as objects; sub-messages as objects; null means absent.
 * (A 64-bit value above 2^63 - 1 must be a string: jansson reads JSON
 * numbers into a long long.)
 * Unknown fields, two members of one oneof, a field given twice (under both
 * of its names) and values of the wrong type are errors, reported as an
 * mpm_error whose field is the path of the offending value (the keys as the
 * input spelled them, rendered by mpm_error_field()), e.g. with
 * mpm_error_text(MPM_FIELD_JSON):
 *   "materials[0].youngsModulus: expected a number, got string \"ten\"".
 *
 * protobuf -> JSON: lowerCamelCase names in field-number order, only the
 * fields that are present (proto2 has_ flags, non-NULL strings/messages,
 * the set member of a oneof, non-empty repeated fields); 64-bit integers as
 * strings; doubles in the shortest form that reads back exactly.
 *
 * Messages built here are allocated with malloc in the layout protobuf-c's
 * unpacker uses, so protobuf_c_message_free_unpacked(msg, NULL) frees them.
 * Well-known types (Timestamp, Any, wrappers, ...) get no special mapping.
 */
#ifndef MPP_JSON_H
#define MPP_JSON_H

#include <stddef.h>

#include <protobuf-c/protobuf-c.h>

#include "mpm_error.h"

/* Flags for mpp_json_from_pb(). */
#define MPP_JSON_PRETTY 1u /* indent two spaces, one field per line */

/* Deepest message nesting accepted in either direction. */
#define MPP_JSON_MAX_DEPTH 64

/* Parses `len` bytes of JSON text (a JSON object) into a new message of
 * type `desc`.  On success stores it in *out (free it with
 * protobuf_c_message_free_unpacked(*out, NULL)) and returns 0; otherwise
 * sets *out to NULL, fills err (may be NULL) and returns MPM_ESYNTAX (not
 * JSON: the message names the line and column), MPM_EINVAL (JSON that does
 * not fit the message type) or MPM_ENOMEM. */
int mpp_json_to_pb(const ProtobufCMessageDescriptor *desc, const char *text, size_t len,
                   ProtobufCMessage **out, mpm_error *err);

/* Prints a message as JSON text.  flags: 0 (compact, one line) or
 * MPP_JSON_PRETTY (ends with a newline).  On success stores a malloc'd,
 * NUL-terminated string in *out (the caller frees it) and returns 0;
 * otherwise sets *out to NULL, fills err and returns MPM_EINVAL (a string
 * that is not UTF-8, a NULL array element, nesting too deep) or
 * MPM_ENOMEM. */
int mpp_json_from_pb(const ProtobufCMessage *msg, unsigned flags, char **out, mpm_error *err);

/* Writes the JSON (lowerCamelCase) name of a .proto field name into buf:
 * underscores are dropped and the letter after one is upper-cased
 * ("youngs_modulus" -> "youngsModulus").  Returns the length of the full
 * name (as snprintf does: the result was truncated if >= len). */
size_t mpp_json_name(const char *proto_name, char *buf, size_t len);

/* Whether the NUL-terminated string s is valid UTF-8 (no overlong forms,
 * no surrogates), as JSON text requires. */
int mpp_json_utf8_valid(const char *s);

/* A double written as the JSON mapping writes it in a string: "NaN",
 * "Infinity", "-Infinity" or a decimal number.  Returns 0 with *out set,
 * MPM_ESYNTAX for other text, MPM_ETOOBIG when the number overflows. */
int mpp_json_double_text(const char *s, double *out);

#endif
