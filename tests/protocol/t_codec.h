/*
 * t_codec.h - what the codec tests (tests/protocol/t_codec_*.c) share: the
 * protocol library's calls with their error as text.
 */
#ifndef T_CODEC_H
#define T_CODEC_H

#include "t.h"

#include "mpmd.pb-c.h"
#include "mpp_case.h"
#include "mpp_json.h"
#include "mpp_msg.h"

/* mpp_case_from_pb under the default particle limit, the error as text. */
static inline int from_pb(const Mpmd__Case *pb, mpp_case **out, char *err)
{
    mpm_error e;
    return t_errtext(mpp_case_from_pb(pb, 0, out, &e), &e, err);
}

static inline int case_to_json(const Mpmd__Case *pb, unsigned flags, char **json, char *err)
{
    mpm_error e;
    return t_errtext(mpp_case_to_json(pb, flags, json, &e), &e, err);
}

static inline int req_decode(const void *buf, size_t n, size_t max, mpp_request *rq, char *err)
{
    mpm_error e;
    return t_errtext(mpp_request_decode(buf, n, max, rq, &e), &e, err);
}

#endif
