/*
 * srv_ckpt.h - checkpoint files of the daemon's runs: where they
 * live, writing one atomically, reading one back verified, removing it.
 *
 * A run's checkpoint is the file "<db>.ckpt/run-<id>.ckpt" beside the
 * database (the directory mode 0700): a header (format, run id, the step,
 * simulated time and next energy-sample seq it holds, the length of the
 * solver's blob, a checksum of header and blob) followed by the blob of
 * mpm_sim_checkpoint_save().  It is written to "run-<id>.ckpt.tmp",
 * fsync()ed, renamed over the last one and the directory fsync()ed, so a
 * crash at any point leaves the previous checkpoint (or none) whole; stray
 * temp files are removed when the daemon starts.  The file, not the run
 * record, is what a resume continues from: the record (store_run_checkpoint)
 * may lag it by one batch after a crash.
 */
#ifndef SRV_CKPT_H
#define SRV_CKPT_H

#include <stddef.h>
#include <stdint.h>

#include "mpm.h"
#include "store.h"

/* Bytes of a checkpoint file before the solver's blob. */
#define SRV_CKPT_HEADER 64

/* A checkpoint read back: the record of its header and the solver's blob
 * (blob_len bytes inside `buf`, which srv_ckpt_file_clear() frees). */
typedef struct {
    store_checkpoint rec; /* step, t, bytes (the file's size), energy_seq */
    uint8_t *buf;
    const uint8_t *blob;
    size_t blob_len;
} srv_ckpt_file;

/* A growing buffer a job reuses for its checkpoints (no fresh pages per
 * checkpoint); free() buf when done. */
typedef struct {
    uint8_t *buf;
    size_t cap;
} srv_ckpt_buf;

/* The file of run `run`'s checkpoint (temp: its temp file) into buf.
 * Returns 0, or -1 when it does not fit. */
int srv_ckpt_path(const char *db, int64_t run, int temp, char *buf, size_t len);

/* Creates "<db>.ckpt" (0700) if it is missing and removes the temp files a
 * crash left there.  0, or -1 with a message in err. */
int srv_ckpt_init(const char *db, char *err, size_t errlen);

/* Saves sim (between steps) as run `run`'s checkpoint, its next energy
 * sample taking seq energy_seq; on success fills *rec.  0, or a negative
 * MPM_E* code (MPM_EIO: a file error, MPM_ENOMEM) with a message in err;
 * the previous checkpoint is then intact. */
int srv_ckpt_write(const char *db, int64_t run, const mpm_sim *sim, int64_t energy_seq,
                   srv_ckpt_buf *b, store_checkpoint *rec, char *err, size_t errlen);

/* Reads run `run`'s checkpoint and checks its header and checksum (not
 * yet the solver's view of the blob: mpm_sim_checkpoint_load() does that).
 * 0; MPM_ENOTFOUND when there is none; MPM_ESYNTAX when it is damaged
 * (truncated, a checksum or header mismatch); MPM_EIO, MPM_ENOMEM; err
 * says which. */
int srv_ckpt_read(const char *db, int64_t run, srv_ckpt_file *out, char *err, size_t errlen);
void srv_ckpt_file_clear(srv_ckpt_file *f);

/* Removes run `run`'s checkpoint file (none: 0).  0 or -1 (errno). */
int srv_ckpt_remove(const char *db, int64_t run);

#endif
