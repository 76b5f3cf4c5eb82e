/*
 * srv_read.h - the daemon's read requests and a Cancel's action
 * (srv_read.c).  Main thread only.
 */
#ifndef SRV_READ_H
#define SRV_READ_H

#include "srv_daemon_int.h"

#include <stdint.h>
#include <zmq.h>

/* Answers a read request (Cancel's and Status' RunInfo, GetRun,
 * ListRuns, GetEnergy, GetSnapshot) from committed data. */
void srv_answer_read(daemon_t *d, zmq_msg_t *id, const char *owner, mpp_request *rq);
/* A cancel's action: 0 when the job was live (its reply, the run, follows
 * once the store has it), 1 when it was answered with an error. */
int srv_cancel_job(daemon_t *d, zmq_msg_t *id, const char *owner, uint64_t job);

#endif
