/*
 * runner.c - runs the tests registered with TEST().  Usage:
 *   mpmtest            run every test
 *   mpmtest NAME...    run the tests whose name contains one of NAME
 *   mpmtest --list     list the test names
 * Prints one line per test with its time, then "N passed, N failed".
 * Exit status 0 only if every selected test passed and at least one ran.
 */
#define _GNU_SOURCE
#include "t.h"

#include <ftw.h>
#include <stdarg.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>
#include <unistd.h>

#define T_MAX 512
static struct {
    const char *name;
    t_fn fn;
} tests[T_MAX];
static int ntests;
static int cur_failed;
static char tmpdir[256];

void t_register(const char *name, t_fn fn)
{
    if (ntests == T_MAX) {
        fprintf(stderr, "runner: more than %d tests; raise T_MAX\n", T_MAX);
        exit(2);
    }
    tests[ntests].name = name;
    tests[ntests].fn = fn;
    ntests++;
}

void t_fail(const char *file, int line, const char *fmt, ...)
{
    va_list ap;
    cur_failed = 1;
    fprintf(stdout, "    FAIL %s:%d: ", file, line);
    va_start(ap, fmt);
    vfprintf(stdout, fmt, ap);
    va_end(ap);
    fputc('\n', stdout);
    fflush(stdout);
}

int t_failed(void)
{
    return cur_failed;
}

const char *t_tmpdir(void)
{
    if (!tmpdir[0]) {
        const char *base = getenv("TMPDIR");
        snprintf(tmpdir, sizeof tmpdir, "%s/mpmtest.XXXXXX", base && *base ? base : "/tmp");
        if (!mkdtemp(tmpdir)) {
            perror("runner: mkdtemp");
            exit(2);
        }
    }
    return tmpdir;
}

static int rm_one(const char *path, const struct stat *sb, int flag, struct FTW *ftw)
{
    (void)sb;
    (void)flag;
    (void)ftw;
    return remove(path);
}

static int cmp_name(const void *a, const void *b)
{
    return strcmp(*(const char *const *)a, *(const char *const *)b);
}

static double now(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return ts.tv_sec + 1e-9 * ts.tv_nsec;
}

int main(int argc, char **argv)
{
    int passed = 0, failed = 0;
    const char *failed_names[T_MAX];
    if (argc > 1 && (!strcmp(argv[1], "--help") || !strcmp(argv[1], "-h"))) {
        printf("usage: %s [--list] [NAME...]\n"
               "  runs every test, or those whose name contains a NAME\n",
               argv[0]);
        return 0;
    }
    /* constructor order is link order; run in name order */
    {
        const char *names[T_MAX] = {0};
        t_fn fns[T_MAX] = {0};
        for (int i = 0; i < ntests; i++) names[i] = tests[i].name;
        qsort(names, ntests, sizeof names[0], cmp_name);
        for (int i = 0; i < ntests; i++)
            for (int j = 0; j < ntests; j++)
                if (tests[j].name == names[i]) fns[i] = tests[j].fn;
        for (int i = 0; i < ntests; i++) {
            tests[i].name = names[i];
            tests[i].fn = fns[i];
        }
    }
    if (argc > 1 && !strcmp(argv[1], "--list")) {
        for (int i = 0; i < ntests; i++) puts(tests[i].name);
        return 0;
    }
    setvbuf(stdout, NULL, _IOLBF, 0);
    double t_all = now();
    for (int i = 0; i < ntests; i++) {
        int sel = argc <= 1;
        for (int a = 1; a < argc && !sel; a++) sel = strstr(tests[i].name, argv[a]) != NULL;
        if (!sel) continue;
        printf("%s\n", tests[i].name);
        cur_failed = 0;
        tmpdir[0] = 0;
        double t0 = now();
        tests[i].fn();
        double dt = now() - t0;
        if (tmpdir[0] && !cur_failed)
            nftw(tmpdir, rm_one, 16, FTW_DEPTH | FTW_PHYS);
        else if (tmpdir[0])
            printf("    (kept %s)\n", tmpdir);
        printf("  %s %s (%.2f s)\n", cur_failed ? "FAIL" : "ok  ", tests[i].name, dt);
        if (cur_failed)
            failed_names[failed++] = tests[i].name;
        else
            passed++;
    }
    printf("\n");
    for (int i = 0; i < failed; i++) printf("failed: %s\n", failed_names[i]);
    printf("total time %.1f s\n", now() - t_all);
    printf("%d passed, %d failed\n", passed, failed);
    if (passed + failed == 0) {
        fprintf(stderr, "runner: no test matched\n");
        return 1;
    }
    return failed ? 1 : 0;
}
