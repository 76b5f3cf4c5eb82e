/*
 * fuzz_json.c - libFuzzer target: the JSON path.  JSON case text (a case
 * file `mpmctl submit` reads) goes through the protobuf JSON mapping
 * (protocol/mpp_json.c: mpp_case_from_json) and the case conversion and
 * check (mpp_case_from_pb, as mpp_case_load does; never mpm_sim_new); a
 * case that parses is written back as JSON and that text must parse again.
 */
#include "fuzz.h"

#include <string.h>

#include "mpp_case.h"

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    Mpmd__Case *pb = NULL;
    mpm_error err;
    int rc = mpp_case_from_json((const char *)data, size, &pb, &err);
    fuzz_check_error(rc, &err);
    if (rc) return 0;
    mpp_case *mc = NULL;
    rc = mpp_case_from_pb(pb, FUZZ_MAX_PARTICLES, &mc, &err);
    fuzz_check_error(rc, &err);
    if (rc == 0 && (!mc || mc->info.particles > FUZZ_MAX_PARTICLES)) abort();
    mpp_case_destroy(&mc);
    char *json = NULL;
    rc = mpp_case_to_json(pb, 0, &json, &err);
    fuzz_check_error(rc, &err);
    if (rc == 0) {
        Mpmd__Case *again = NULL;
        /* what the mapping writes, it reads */
        if (mpp_case_from_json(json, strlen(json), &again, &err)) abort();
        mpp_case_pb_free(&again);
    }
    free(json);
    mpp_case_pb_free(&pb);
    return 0;
}
