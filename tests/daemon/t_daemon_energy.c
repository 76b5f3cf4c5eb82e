/*
 * t_daemon_energy.c - integration tests of the extended energy balance
 * through a real mpmd (ipc:// in the test's temporary
 * directory, a real SQLite file) to mpmctl: the energy budget's warning
 * and FAILED on the paper's GIMP MUSL bar that gains energy, the balance
 * error in RunInfo, `runs` and `show`, and the new EnergySample fields
 * (damping work, balance error) as the stream and the store carry them.
 */
#define _GNU_SOURCE
#include "t_daemon.h"
#include "t_daemon_util.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

/* The GIMP MUSL bar of 13 cells of one point at dt = 0.5 x the CFL limit
 * (10 empty cells beyond its end), 8000 steps: its total energy ends near
 * 1.85 E0 (tests/solver/t_energy.c). */
static json_t *gaining_bar(int fail_on_budget)
{
    json_t *c = example("bar1d_gimp");
    if (!c) return NULL;
    double h = 1.0 / 13;
    json_object_del(c, "endTime");
    json_object_set_new(c, "steps", json_integer(8000));
    json_object_set_new(c, "update", json_string("MUSL"));
    json_object_set_new(c, "dt", json_real(0.5 * h / (sqrt(10.0) + 0.1)));
    json_object_set_new(json_object_get(c, "grid"), "nodes", json_pack("[i]", 24));
    if (fail_on_budget) json_object_set_new(c, "failOnBudget", json_true());
    set_output(c, "energyEvery", json_integer(100));
    return c;
}

DTEST(daemon_energy_budget_warning_and_failed)
{
    const char *tmp = t_tmpdir();
    const char *extra[] = {"--workers", "1", "--solver-threads", "1", NULL};
    char dir[300], path[400];
    td_daemon d;
    td_out o;
    snprintf(dir, sizeof dir, "%s/d", tmp);
    if (td_start(&d, dir, extra)) return;

    /* default budget (5 %): FINISHED with the warning */
    CHECK(write_case(gaining_bar(0), dir, "warn.json", path, sizeof path) == 0);
    CHECK(td_ctl(&d, 120, &o, "submit", path, "--watch", NULL) == 0);
    CHECKF(o.status == 0, "submit --watch: exit %d, stderr: %s", o.status, o.err);
    CHECKF(strstr(o.out, "energy balance error") && strstr(o.out, "  warning: energy balance"),
           "the watch summary lacks the balance and the warning: %s", o.out);
    td_out_free(&o);
    json_t *r = show_json(&d, 1);
    CHECK(r);
    double bal = jnum(r, "balanceError");
    const char *w = jstr(r, "warning");
    TLOG("GIMP MUSL bar through mpmd: status %s, balanceError %.4f, warning \"%s\"",
         jstr(r, "status"), bal, w ? w : "");
    CHECK(!strcmp(jstr(r, "status"), "FINISHED"));
    CHECK(bal > 0.5 && bal < 2);
    CHECK(strstr(w, "exceeds the budget 5%") != NULL);
    const json_t *le = json_object_get(r, "lastEnergy");
    CHECK(le && jnum(le, "balanceError") > 0.5 && jnum(le, "balanceError") <= bal);
    json_decref(r);

    /* show (text) and runs print them */
    CHECK(td_ctl(&d, 30, &o, "show", "1", NULL) == 0 && o.status == 0);
    CHECKF(strstr(o.out, "  balance     error ") && strstr(o.out, "  warning     energy balance"),
           "show: %s", o.out);
    td_out_free(&o);
    CHECK(td_ctl(&d, 30, &o, "runs", NULL) == 0 && o.status == 0);
    char want[32];
    snprintf(want, sizeof want, "%.3g%%!", 100 * bal);
    CHECKF(strstr(o.out, " BALANCE ") && strstr(o.out, want), "runs (want %s): %s", want, o.out);
    td_out_free(&o);

    /* failOnBudget: FAILED, the reason as the run's error, no warning */
    CHECK(write_case(gaining_bar(1), dir, "fail.json", path, sizeof path) == 0);
    CHECK(td_ctl(&d, 120, &o, "submit", path, "--watch", NULL) == 0);
    CHECKF(o.status == 3, "submit --watch with failOnBudget: exit %d (want 3, FAILED)", o.status);
    td_out_free(&o);
    r = show_json(&d, 2);
    CHECK(r);
    CHECK(!strcmp(jstr(r, "status"), "FAILED"));
    CHECK(strstr(jstr(r, "error"), "energy_budget") != NULL);
    CHECK(!json_object_get(r, "warning"));
    CHECK(jnum(r, "balanceError") == bal); /* the same run, the same bits */
    json_decref(r);

    /* energyBudget 0: no check, no warning (the balance is still recorded) */
    json_t *c = gaining_bar(0);
    json_object_set_new(c, "energyBudget", json_real(0));
    json_object_set_new(c, "steps", json_integer(400));
    CHECK(write_case(c, dir, "nobudget.json", path, sizeof path) == 0);
    CHECK(td_ctl(&d, 120, &o, "submit", path, "--watch", NULL) == 0 && o.status == 0);
    td_out_free(&o);
    r = show_json(&d, 3);
    CHECK(r && !json_object_get(r, "warning") && json_object_get(r, "balanceError"));
    json_decref(r);
}

/* Damping work and the balance error as the stream carries them
 * (`submit --watch --json`: the live EnergySample messages decoded by
 * mpmctl, gaps filled from the store) and as the store keeps them
 * (`energy --json`): the same values, sample for sample, growing damping
 * work, and a balance error that stays within 1 % (the bar under viscous
 * damping, tests/solver/t_energy.c). */
/* The solver's warnings reach the run record: the example's pushed bar
 * (proto/examples/pushed_bar1d.json) driven ten times faster, so that its
 * face moves 0.5 cells by the end (mpm_sim_warnings(): more than 0.05),
 * finishes with the warning in show's JSON and text. */
DTEST(daemon_solver_warning_recorded)
{
    const char *tmp = t_tmpdir();
    const char *extra[] = {"--workers", "1", "--solver-threads", "1", NULL};
    char dir[300], path[400];
    td_daemon d;
    td_out o;
    snprintf(dir, sizeof dir, "%s/d", tmp);
    if (td_start(&d, dir, extra)) return;
    json_error_t je;
    json_t *c = json_load_file("proto/examples/pushed_bar1d.json", 0, &je);
    CHECKF(c, "%s", je.text);
    json_t *pr = json_array_get(json_object_get(c, "prescribed"), 0);
    CHECK(pr && !json_object_set_new(pr, "velocity", json_pack("[f]", 0.01)));
    CHECK(write_case(c, dir, "fast.json", path, sizeof path) == 0);
    CHECK(td_ctl(&d, 120, &o, "submit", path, "--watch", NULL) == 0);
    CHECKF(o.status == 0, "submit --watch: exit %d, stderr: %s", o.status, o.err);
    CHECKF(strstr(o.out, "  warning: prescribed[0] moved face x_lo 0.498 cells"), "watch: %s",
           o.out);
    td_out_free(&o);
    json_t *r = show_json(&d, 1);
    CHECK(r);
    const char *w = jstr(r, "warning");
    TLOG("pushed bar at 10 x v0: status %s, warning \"%s\"", jstr(r, "status"), w ? w : "");
    CHECK(!strcmp(jstr(r, "status"), "FINISHED"));
    CHECK(w && strstr(w, "prescribed[0] moved face x_lo 0.498 cells") != NULL);
    json_decref(r);
    CHECK(td_ctl(&d, 30, &o, "show", "1", NULL) == 0 && o.status == 0);
    CHECKF(strstr(o.out, "  warning     prescribed[0] moved face"), "show: %s", o.out);
    td_out_free(&o);
    /* the example itself moves its face 0.05 cells: no warning */
    CHECK(td_ctl(&d, 120, &o, "submit", "proto/examples/pushed_bar1d.json", "--watch", NULL) == 0);
    CHECKF(o.status == 0 && !strstr(o.out, "warning:"), "example: exit %d, %s", o.status, o.out);
    td_out_free(&o);
}

DTEST(daemon_energy_stream_carries_damping)
{
    const char *tmp = t_tmpdir();
    const char *extra[] = {"--workers", "1", "--solver-threads", "1", NULL};
    char dir[300], path[400];
    td_daemon d;
    td_out o, e;
    snprintf(dir, sizeof dir, "%s/d", tmp);
    if (td_start(&d, dir, extra)) return;
    json_t *c = bar_steps(2000, 50);
    CHECK(c);
    json_object_set_new(c, "damping",
                        json_pack("{s:s,s:f}", "kind", "VISCOUS", "coefficient", 1.0));
    CHECK(write_case(c, dir, "damped.json", path, sizeof path) == 0);
    CHECK(td_ctl(&d, 120, &o, "submit", path, "--watch", "--json", NULL) == 0);
    CHECKF(o.status == 0, "exit %d: %s", o.status, o.err);
    CHECK(td_ctl(&d, 30, &e, "energy", "1", "--json", NULL) == 0 && e.status == 0);
    CHECKF(!strcmp(o.out, e.out), "the streamed series differs from the stored one");
    char **lines = NULL;
    size_t n = td_lines(o.out, &lines);
    double prev = 0, worst = 0, e0 = 0;
    int ok = n == 41;
    for (size_t i = 0; ok && i < n; i++) {
        json_t *s = parse_line(lines[i]);
        /* absent: 0 (sent only when non-zero) */
        double dw = json_object_get(s, "dampingWork") ? jnum(s, "dampingWork") : 0;
        double be = json_object_get(s, "balanceError") ? jnum(s, "balanceError") : 0;
        if (i == 0) e0 = jnum(s, "total");
        ok = s && (i == 0 ? !json_object_get(s, "dampingWork") : dw > prev) &&
             !json_object_get(s, "plasticWork") && !json_object_get(s, "frictionWork");
        if (!ok) TLOG("sample %zu: %s", i, lines[i]);
        prev = dw;
        worst = fmax(worst, be);
        json_decref(s);
    }
    TLOG("damped bar through mpmd: %zu samples, damping work %.4f E0 at the end, balance error "
         "%.2e at worst",
         n, prev / e0, worst);
    free(lines);
    CHECK(ok);
    CHECK(prev > 0.5 * e0);
    CHECK(worst > 0 && worst < 0.03);
    td_out_free(&o);
    td_out_free(&e);
}
