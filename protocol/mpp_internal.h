/*
 * mpp_internal.h - private to the protocol library (the .c files in protocol/): the one
 * header that includes the generated mpmd.pb-c.h, and the helpers the
 * library's files share (pack / unpack with the size limit, the
 * EnergySample and Snapshot message fills).  Nothing outside protocol/
 * includes it.
 */
#ifndef MPP_INTERNAL_H
#define MPP_INTERNAL_H

#include <stddef.h>
#include <stdint.h>

#include "mpmd.pb-c.h"
#include "mpp.h"
#include "mpp_case.h"
#include "mpp_json.h"
#include "mpp_msg.h"

/* Packs m into a malloc'd *buf of *len bytes (never NULL on success, even
 * for 0 bytes).  Returns 0 or MPM_ENOMEM. */
int mpp_pack(const ProtobufCMessage *m, uint8_t **buf, size_t *len);

/* Unpacks len bytes as a message of type d, refusing more than max bytes
 * (0: MPP_MSG_MAX) with MPM_ETOOBIG and undecodable bytes with MPM_ESYNTAX.
 * *out is NULL on error; free it with protobuf_c_message_free_unpacked(). */
int mpp_unpack(const ProtobufCMessageDescriptor *d, const void *buf, size_t len, size_t max,
               ProtobufCMessage **out, mpm_error *err);

/* An EnergySample message for s, every field present (momentum and
 * angular_momentum point into s: dim momentum entries; angular momentum
 * x, y, z in 3D, z alone in 2D, none in 1D). */
void mpp_fill_energy(Mpmd__EnergySample *es, const mpm_energy_sample *s);
/* The sample an EnergySample message holds (NULL: all zero). */
void mpp_take_energy(mpm_energy_sample *s, const Mpmd__EnergySample *e);
/* A Snapshot message for s (the arrays point into s). */
void mpp_fill_snapshot(Mpmd__Snapshot *ps, const mpp_snapshot *s);
/* The snapshot a Snapshot message holds (the arrays point into it).
 * Returns 0, or MPM_ESYNTAX when an array does not hold n times its width
 * values (or dim is not 1..3 while x or v is present). */
int mpp_take_snapshot(mpp_snapshot *s, const Mpmd__Snapshot *ps, mpm_error *err);

#endif
