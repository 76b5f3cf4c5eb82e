/*
 * fuzz_request.c - libFuzzer target: the daemon's request path without a
 * daemon.  A frame as mpmd receives it goes through the decoder mpmd calls
 * (mpp_request_decode, under the default --max-request-bytes); a Submit's
 * case is then converted and checked as do_submit() does
 * (mpp_case_from_pb: the codec's checks and mpm_case_check, never
 * mpm_sim_new), pinned and packed for the store; and the reply mpmd would
 * send (SubmitOk, or the error rendered by mpp_reply_error_from) is
 * encoded and decoded back as a client would, and must say the same.
 */
#include "fuzz.h"

#include "mpp_case.h"
#include "mpp_msg.h"

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    mpp_request rq;
    mpm_error err;
    uint8_t *buf = NULL;
    size_t len = 0;
    int rc = mpp_request_decode(data, size, FUZZ_MAX_REQUEST, &rq, &err);
    fuzz_check_error(rc, &err);
    if (rc == 0 && rq.kind == MPP_REQ_SUBMIT) {
        mpp_case *mc = NULL;
        rc = mpp_case_from_pb(rq.case_pb, FUZZ_MAX_PARTICLES, &mc, &err);
        fuzz_check_error(rc, &err);
        if (rc == 0) {
            uint8_t *pb = NULL;
            size_t pblen = 0;
            if (!mc || mc->info.particles > FUZZ_MAX_PARTICLES) abort();
            mpp_case_pin_defaults(rq.case_pb);
            if (mpp_case_pack(rq.case_pb, &pb, &pblen)) abort();
            free(pb);
            rc = mpp_reply_submit_ok(1, 1, &buf, &len);
        }
        mpp_case_destroy(&mc);
    }
    if (rc) {
        if (mpp_reply_error_from(&err, &buf, &len)) abort();
        mpp_reply r;
        mpm_error e2;
        if (mpp_reply_decode(buf, len, 0, &r, &e2) || r.kind != MPP_REPLY_ERROR ||
            !r.err_message[0])
            abort();
        mpp_reply_clear(&r);
    }
    free(buf);
    mpp_request_clear(&rq);
    return 0;
}
