/*
 * fuzz_stream.c - libFuzzer target: what a client decodes from the daemon.
 * The same bytes go through the stream decoder `mpmctl watch` calls on
 * every StreamMsg (mpp_stream_decode) and the Reply decoder every command
 * calls (mpp_reply_decode); what decodes is rendered as `--json` renders
 * it (energy samples and snapshots to JSON).
 */
#include "fuzz.h"

#include "mpp_msg.h"

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    mpm_error err;
    char *json = NULL;
    mpp_stream s;
    int rc = mpp_stream_decode(data, size, 0, &s, &err);
    fuzz_check_error(rc, &err);
    if (rc == 0 &&
        (s.kind == MPP_STREAM_ENERGY || (s.kind == MPP_STREAM_FINISHED && s.has_energy))) {
        rc = mpp_energy_to_json(&s.energy, &json, &err);
        fuzz_check_error(rc, &err);
        free(json);
        json = NULL;
    }
    if (rc == 0 && s.kind == MPP_STREAM_SNAPSHOT) {
        rc = mpp_snapshot_to_json(&s.snapshot, &json, &err);
        fuzz_check_error(rc, &err);
        free(json);
        json = NULL;
    }
    mpp_stream_clear(&s);

    mpp_reply r;
    rc = mpp_reply_decode(data, size, 0, &r, &err);
    fuzz_check_error(rc, &err);
    if (rc == 0 && r.kind == MPP_REPLY_SNAPSHOT) {
        rc = mpp_snapshot_to_json(&r.snapshot, &json, &err);
        fuzz_check_error(rc, &err);
        free(json);
        json = NULL;
    }
    for (size_t i = 0; rc == 0 && r.kind == MPP_REPLY_ENERGY && i < r.n_samples && i < 4; i++) {
        rc = mpp_energy_to_json(&r.samples[i], &json, &err);
        fuzz_check_error(rc, &err);
        free(json);
        json = NULL;
    }
    mpp_reply_clear(&r);
    return 0;
}
