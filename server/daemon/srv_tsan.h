/*
 * srv_tsan.h - ThreadSanitizer's view of a message handed to libzmq
 * without a copy.  libzmq's lock-free pipes are not instrumented, so TSan
 * cannot see that what a thread wrote into a message before sending it
 * happens before libzmq's free function runs on its I/O thread: the
 * sender calls TSAN_RELEASE(p) before the send, the free function
 * TSAN_ACQUIRE(p) first (srv_outq.c's replies, srv_job.c's snapshots;
 * guarded by make tsan).  Without -fsanitize=thread both do nothing.
 */
#ifndef SRV_TSAN_H
#define SRV_TSAN_H

#if defined(__SANITIZE_THREAD__)
void __tsan_acquire(void *addr);
void __tsan_release(void *addr);
#define TSAN_ACQUIRE(p) __tsan_acquire(p)
#define TSAN_RELEASE(p) __tsan_release(p)
#else
#define TSAN_ACQUIRE(p) ((void)(p))
#define TSAN_RELEASE(p) ((void)(p))
#endif

#endif
