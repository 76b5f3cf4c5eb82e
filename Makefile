# mpmd build.  `make` builds everything; `make test` installs missing Debian
# packages, builds the sanitizer build and runs every test; `make bench` runs
# the benchmarks.  Modules are picked up by wildcard: a new server/mpm/mpm_*.c
# joins the solver library, a new server/*.c the daemon library, a new
# tests/t_*.c the test runner.

CC      ?= cc
CSTD    := -std=c11 -D_POSIX_C_SOURCE=200809L -D_DEFAULT_SOURCE
WARN    := -Wall -Wextra -Werror -Wshadow -Wpointer-arith -Wstrict-prototypes -Wmissing-prototypes
OPT     ?= -O2 -g
SAN     := -O1 -g -fsanitize=address,undefined -fno-omit-frame-pointer -fno-sanitize-recover=all
LDLIBS  := -lm -lpthread
SRVLIBS := -lzmq -lsqlite3 -lprotobuf-c -ljansson

MPM_SRCS  := $(wildcard server/mpm/mpm_*.c)
SRV_SRCS  := $(filter-out server/main.c,$(wildcard server/*.c))
CODEC_SRCS := server/srv_codec.c server/srv_json.c
CLI_SRCS  := $(wildcard clients/*.c)
# binaries whose sources exist (the daemon and the client arrive with issue #3)
PROGS     := $(if $(wildcard server/main.c),mpmd) $(if $(wildcard clients/mpmctl.c),mpmctl)
TEST_SRCS := $(wildcard tests/t_*.c) tests/runner.c
PROTOS    := $(wildcard proto/*.proto)
GEN_C     := $(patsubst proto/%.proto,build/gen/%.pb-c.c,$(PROTOS))
GEN_H     := $(GEN_C:.c=.h)
INC       := -Iserver/mpm -Iserver -Iprotocol -Ibuild/gen -Itests

# Two builds: release (build/rel, bin/) and sanitizers (build/asan).
REL  := build/rel
ASAN := build/asan

.PHONY: all deps test test-quick bench demo clean
.SECONDARY: $(GEN_C) $(GEN_H)
all: bin/mpmtest bin/mpmrun $(addprefix bin/,$(PROGS))

deps:
	@bash deploy/install-deps.sh

build/gen/%.pb-c.c build/gen/%.pb-c.h: proto/%.proto
	@mkdir -p build/gen
	protoc-c --proto_path=proto --c_out=build/gen $<

# Objects: $(1) build dir, $(2) flags
define objs
$(1)/%.o: %.c $(GEN_H) $(wildcard server/mpm/*.h server/*.h protocol/*.h tests/*.h clients/*.h)
	@mkdir -p $$(dir $$@)
	$$(CC) $$(CSTD) $$(WARN) $(2) $$(INC) -c $$< -o $$@
$(1)/gen/%.o: build/gen/%.c $(GEN_H)
	@mkdir -p $$(dir $$@)
	$$(CC) $$(CSTD) $(2) $$(INC) -c $$< -o $$@
endef
$(eval $(call objs,$(REL),$(OPT)))
$(eval $(call objs,$(ASAN),$(SAN)))

mpm_objs  = $(patsubst %.c,$(1)/%.o,$(MPM_SRCS))
srv_objs  = $(patsubst %.c,$(1)/%.o,$(SRV_SRCS)) $(patsubst build/gen/%.c,$(1)/gen/%.o,$(GEN_C))
test_objs = $(patsubst %.c,$(1)/%.o,$(TEST_SRCS))
codec_objs = $(patsubst %.c,$(1)/%.o,$(CODEC_SRCS)) $(patsubst build/gen/%.c,$(1)/gen/%.o,$(GEN_C))
cli_objs  = $(patsubst %.c,$(1)/%.o,$(CLI_SRCS))

# The daemon: server/main.c + the daemon library + the solver.
bin/mpmd: $(REL)/server/main.o $(call srv_objs,$(REL)) $(call mpm_objs,$(REL))
	@mkdir -p bin
	$(CC) $(OPT) -o $@ $^ $(SRVLIBS) $(LDLIBS)
$(ASAN)/mpmd: $(ASAN)/server/main.o $(call srv_objs,$(ASAN)) $(call mpm_objs,$(ASAN))
	$(CC) $(SAN) -o $@ $^ $(SRVLIBS) $(LDLIBS)

# The client: clients/*.c + the codec (it checks cases before sending).
bin/mpmctl: $(call cli_objs,$(REL)) $(call codec_objs,$(REL)) $(call mpm_objs,$(REL))
	@mkdir -p bin
	$(CC) $(OPT) -o $@ $^ -lzmq -lprotobuf-c -ljansson $(LDLIBS)
$(ASAN)/mpmctl: $(call cli_objs,$(ASAN)) $(call codec_objs,$(ASAN)) $(call mpm_objs,$(ASAN))
	$(CC) $(SAN) -o $@ $^ -lzmq -lprotobuf-c -ljansson $(LDLIBS)

bin/mpmtest: $(call test_objs,$(REL)) $(call srv_objs,$(REL)) $(call mpm_objs,$(REL))
	@mkdir -p bin
	$(CC) $(OPT) -o $@ $^ $(if $(SRV_SRCS)$(PROTOS),$(SRVLIBS)) $(LDLIBS)

$(ASAN)/mpmtest: $(call test_objs,$(ASAN)) $(call srv_objs,$(ASAN)) $(call mpm_objs,$(ASAN))
	$(CC) $(SAN) -o $@ $^ $(if $(SRV_SRCS)$(PROTOS),$(SRVLIBS)) $(LDLIBS)

# Tools that need only the solver library.
bin/%: $(REL)/server/tools/%.o $(call mpm_objs,$(REL))
	@mkdir -p bin
	$(CC) $(OPT) -o $@ $^ $(LDLIBS)

# make demo: mpmd on loopback with its default database, the paper's fine
# bouncing disks submitted and watched live with mpmctl, then stopped.
demo: deps
	@$(MAKE) --no-print-directory bin/mpmd bin/mpmctl
	bash deploy/demo.sh

# make test: every test under ASan+UBSan.  T=name runs one test.
# Tests that need the daemon and the client find them through MPMD_BIN and
# MPMCTL_BIN (the sanitizer builds here).
test: deps
	@$(MAKE) --no-print-directory $(ASAN)/mpmtest $(addprefix $(ASAN)/,$(PROGS))
	ASAN_OPTIONS=detect_leaks=1:abort_on_error=1 UBSAN_OPTIONS=print_stacktrace=1 \
	  MPMD_BIN=$(ASAN)/mpmd MPMCTL_BIN=$(ASAN)/mpmctl $(ASAN)/mpmtest $(T)

# Release build, no sanitizers: quick local iteration.
test-quick: bin/mpmtest $(addprefix bin/,$(PROGS))
	MPMD_BIN=bin/mpmd MPMCTL_BIN=bin/mpmctl bin/mpmtest $(T)

clean:
	rm -rf build bin

# ---- Issue #4: accuracy benchmark and stability stress suite ----------------
# make bench-accuracy  runs bin/mpmbench-accuracy (tests/bench/): method, update,
#                      cells, particles per cell and dt/CFL swept on problems with
#                      known answers; table on the terminal, build/bench/accuracy.csv,
#                      and build/bench/accuracy_{time,space,dt}.png when gnuplot is
#                      there (the target installs gnuplot-nox through
#                      `deploy/install-deps.sh bench`, or skips the plots with a
#                      message).  BENCH_ARGS=--quick for a short run.
# make stress          the full stability suite: the stress_* tests of
#                      tests/t_stress.c with MPM_STRESS=full (CFL sweep, 10^6-step
#                      bar, 10^5-step disks, cell-crossing noise, extremes in-process
#                      and through a real bin/mpmd) on the release build.  `make test`
#                      runs the same tests in their quick form.
.PHONY: bench-accuracy stress
BENCH_SRCS := $(wildcard tests/bench/*.c)
BENCH_OBJS := $(patsubst %.c,$(REL)/%.o,$(BENCH_SRCS))
$(BENCH_OBJS): tests/bench/bench.h
bin/mpmbench-accuracy: $(BENCH_OBJS) $(call mpm_objs,$(REL))
	@mkdir -p bin
	$(CC) $(OPT) -o $@ $^ $(LDLIBS)

bench-accuracy: deps
	@bash deploy/install-deps.sh bench || echo "bench-accuracy: could not install gnuplot-nox; the plots will be skipped"
	@$(MAKE) --no-print-directory bin/mpmbench-accuracy
	bin/mpmbench-accuracy $(BENCH_ARGS)
	@if command -v gnuplot >/dev/null 2>&1; then \
	  gnuplot build/bench/accuracy.gp && echo "plots: build/bench/accuracy_time.png accuracy_space.png accuracy_dt.png"; \
	else echo "bench-accuracy: gnuplot not found, plots skipped (bash deploy/install-deps.sh bench installs it)"; fi

stress: deps
	@$(MAKE) --no-print-directory bin/mpmtest bin/mpmd
	MPM_STRESS=full MPMD_BIN=bin/mpmd bin/mpmtest stress_

# ---- Issue #5: throughput benchmark ------------------------------------------
# make bench  runs bin/mpmbench --all (tests/perf/): disks2d, cube3d and bar1d at
#             ~10^6 particles and sparse2d (10^4 particles in a 4096^2 grid against
#             a tight grid), MPM and GIMP, 1 and 2 threads; disks2d against
#             bin/mpmbench-lean (the same sources on a solver compiled with
#             -DMPM_LEAN, objects in build/lean); disks2d through a real bin/mpmd.
#             Table on the terminal, rows appended to build/bench/throughput.csv.
#             One scene: bin/mpmbench --scene NAME [...] (bin/mpmbench --help).
LEAN := build/lean
$(eval $(call objs,$(LEAN),$(OPT) -DMPM_LEAN))
PERF_SRCS := $(wildcard tests/perf/*.c)
$(patsubst %.c,$(REL)/%.o,$(PERF_SRCS)) $(patsubst %.c,$(LEAN)/%.o,$(PERF_SRCS)): tests/perf/perf.h
bin/mpmbench: $(patsubst %.c,$(REL)/%.o,$(PERF_SRCS)) $(call codec_objs,$(REL)) $(call mpm_objs,$(REL))
	@mkdir -p bin
	$(CC) $(OPT) -o $@ $^ -lzmq -lprotobuf-c -ljansson $(LDLIBS)
# the lean binary has no daemon scene, so it needs only the solver
bin/mpmbench-lean: $(patsubst %.c,$(LEAN)/%.o,$(PERF_SRCS)) $(call mpm_objs,$(LEAN))
	@mkdir -p bin
	$(CC) $(OPT) -o $@ $^ $(LDLIBS)

bench: deps
	@$(MAKE) --no-print-directory bin/mpmbench bin/mpmbench-lean bin/mpmd
	@grep -q MPM_LEAN $(MPM_SRCS) server/mpm/*.h || echo "bench: note: server/mpm does not use MPM_LEAN yet, so bin/mpmbench-lean is the normal solver"
	bin/mpmbench --all
	@echo "bench: rows appended to build/bench/throughput.csv"
