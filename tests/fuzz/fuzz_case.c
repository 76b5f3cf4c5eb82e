/*
 * fuzz_case.c - libFuzzer target: the case codec.  Packed Case bytes (as a
 * Submit carries them, or `mpmctl submit` reads a .pb case) go through the
 * protocol's decoder (mpp_case_unpack) and conversion and check
 * (mpp_case_from_pb: the codec's own checks, then mpm_case_check with a
 * particle limit; never mpm_sim_new); a decoded message is packed again
 * and written as JSON (what `mpmctl show --case` does with a stored case).
 */
#include "fuzz.h"

#include "mpp_case.h"

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    Mpmd__Case *pb = NULL;
    mpm_error err;
    int rc = mpp_case_unpack(data, size, 0, &pb, &err);
    fuzz_check_error(rc, &err);
    if (rc) return 0;
    mpp_case *mc = NULL;
    rc = mpp_case_from_pb(pb, FUZZ_MAX_PARTICLES, &mc, &err);
    fuzz_check_error(rc, &err);
    if (rc == 0 && (!mc || mc->info.particles > FUZZ_MAX_PARTICLES)) abort();
    mpp_case_destroy(&mc);
    uint8_t *buf = NULL;
    size_t len = 0;
    if (mpp_case_pack(pb, &buf, &len)) abort();
    free(buf);
    char *json = NULL;
    rc = mpp_case_to_json(pb, 0, &json, &err);
    fuzz_check_error(rc, &err);
    free(json);
    mpp_case_pb_free(&pb);
    return 0;
}
