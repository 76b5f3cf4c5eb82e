/*
 * srv_budget.h - the daemon's disk budgets: the bytes of recorded
 * snapshots and energy samples a job (--job-max-disk-mb), the whole
 * database (--max-disk-mb) and one client (--client-max-disk-mb) may take.
 *
 * At start the recorded total of every owner is read from the store in one
 * query; from then on the daemon keeps the figures itself: a submission is
 * admitted only if its estimated bytes fit every budget (srv_budget_admit),
 * and a worker charges each write before it makes it (srv_budget_charge):
 * a write that would pass a budget is not made, and the job ends FAILED
 * with the reason.  A record counts as in store_owner_bytes(): a
 * snapshot's data bytes, STORE_ENERGY_ROW_BYTES per energy sample; and a
 * run's checkpoint file at its size while it is on disk (the new one
 * charged before it is written, the one it replaces refunded after the
 * rename, the last refunded when it is removed: srv_job.c).
 * Thread-safe (one mutex, taken per write, never per step).
 */
#ifndef SRV_BUDGET_H
#define SRV_BUDGET_H

#include <stddef.h>
#include <stdint.h>

#include "mpp_case.h"
#include "srv_config.h"
#include "store.h"

typedef struct srv_budget srv_budget;

/* Reads the recorded total of every owner from st.  NULL with a message
 * on failure. */
srv_budget *srv_budget_new(const srv_config *cfg, store *st, char *err, size_t errlen);

/* Frees b; nulls the pointer; NULL is a no-op. */
void srv_budget_destroy(srv_budget **b);

/* What a checked case will record in `steps` steps (the daemon's step
 * estimate, as for --max-steps): snapshots (Output.record_snapshots, every
 * Output.snapshot_every steps, n particles times the bytes of the fields
 * the run will have) and energy samples (the first, every
 * Output.energy_every steps, the last). */
typedef struct {
    double snapshots, snapshot_bytes; /* count, bytes of one */
    double samples;                   /* energy samples */
    double bytes;                     /* the total */
} srv_disk_estimate;
void srv_budget_estimate(const mpp_case *sc, double steps, srv_disk_estimate *out);

/* Admits a submission by owner whose estimate is e, under the client's
 * disk quota quota_mb (srv_auth_quota(); 0: none), which its jobs' writes
 * are then charged against: 0, or MPM_ETOOBIG
 * with err naming the field (output.snapshot_every when the snapshots make
 * most of the bytes, else output.energy_every), the estimate, the budget
 * and its flag.  `automatic`: the step count is the automatic dt's
 * smallest (the message says "at least"). */
int srv_budget_admit(srv_budget *b, const char *owner, long long quota_mb,
                     const srv_disk_estimate *e, int automatic, mpm_error *err);

/* Charges n bytes that a job of owner (*job_bytes recorded so far) is
 * about to record: 0 when they fit every budget (charged: *job_bytes and
 * the totals grow by n; the client's quota is the one its last admitted
 * submission set), else MPM_ETOOBIG with the reason in why (the
 * budget, its flag and the figures; nothing charged). */
int srv_budget_charge(srv_budget *b, const char *owner, int64_t *job_bytes, int64_t n, char *why,
                      size_t whylen);

/* Gives back n bytes charged for a write that was not made. */
void srv_budget_refund(srv_budget *b, const char *owner, int64_t *job_bytes, int64_t n);

/* Bytes recorded (charged) by owner, and by everyone. */
int64_t srv_budget_owner(srv_budget *b, const char *owner);
int64_t srv_budget_total(srv_budget *b);

#endif
