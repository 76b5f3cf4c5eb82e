/*
 * srv_submit.h - the Submit and Resume requests (srv_submit.c).  Main
 * thread only.
 */
#ifndef SRV_SUBMIT_H
#define SRV_SUBMIT_H

#include "srv_daemon_int.h"

#include <zmq.h>

/* Submit: checks the case, the limits, the quotas and the disk budgets,
 * records the run and queues its job; answers SubmitOk or an Error. */
void srv_do_submit(daemon_t *d, zmq_msg_t *id, const char *owner, mpp_request *rq);
/* Resume: an INTERRUPTED run of the requester's (or any, for an admin key)
 * goes on from its checkpoint file; answers SubmitOk or an Error. */
void srv_do_resume(daemon_t *d, zmq_msg_t *id, const char *owner, mpp_request *rq);

#endif
