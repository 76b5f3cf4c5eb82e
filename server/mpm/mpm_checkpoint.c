/*
 * mpm_checkpoint.c -- PLACEHOLDER: the checkpoint API of mpm.h refuses
 * until the implementation lands (it replaces this file).
 */
#include "mpm_internal.h"

size_t mpm_sim_checkpoint_size(const mpm_sim *sim)
{
    (void)sim;
    return 0;
}

int mpm_sim_checkpoint_save(const mpm_sim *sim, void *buf, size_t n)
{
    (void)sim, (void)buf, (void)n;
    return MPM_ESTATE;
}

int mpm_sim_checkpoint_load(mpm_sim *sim, const void *buf, size_t n, mpm_error *err)
{
    (void)sim, (void)buf, (void)n;
    return mpm_fail(err, MPM_ESTATE, "", "checkpoints are not implemented yet");
}
