# mpmd build.  `make` builds everything; `make test` installs missing Debian
# packages, builds the sanitizer build and runs every test; `make bench` runs
# the throughput benchmark (with its STREAM triad roof), and `make bench-compare
# REF=<commit>` the same bench of another commit against this tree's,
# interleaved.  docs/architecture.md tells what each folder owns.
#
# Layers, bottom up (each library a static archive, linked only by what needs
# it; sources are picked up by wildcard, so a new file joins its layer by
# being there).  A library's public headers live in its include/ folder; a
# layer is compiled with the include/ folders of the layers below it and
# nothing else, so an include that crosses a layer the wrong way, or reaches
# another library's private header, does not compile:
#   solver/            libmpm    the solver (plain C, libm, pthreads)
#   protocol/          libmpp    codec, JSON mapping, versions, endpoint rules
#                                (+ the generated build/gen/*.pb-c.c)
#   server/store/      libstore  the SQLite run store
#   server/daemon/     libsrv    the daemon's modules; server/mpmd/ is mpmd
#   clients/ctl/       libctl    the client library of mpmctl and mpmweb
#   clients/mpmctl/              mpmctl;  clients/web/: mpmweb
#   scenes/            libscenes the paper's cases and the collapse; scenes/mpmrun/
#   bench/                       the benchmarks (accuracy/, perf/, ceiling/, vtk/)
#   tests/                       mpmtest: runner.c + tests/<layer>/t_*.c
# Every object records its header dependencies (-MMD -MP), so an edit
# rebuilds only what includes it.

# Parallel by default: as many jobs as CPUs, unless the command line gives -j
# (which wins over this) or this is a recursive $(MAKE), which shares the
# top-level make's job slots.
ifeq ($(MAKELEVEL),0)
MAKEFLAGS += -j$(shell nproc 2>/dev/null || echo 2)
endif

CC      ?= cc
CSTD    := -std=c11 -D_POSIX_C_SOURCE=200809L -D_DEFAULT_SOURCE
WARN    := -Wall -Wextra -Werror -Wshadow -Wpointer-arith -Wstrict-prototypes -Wmissing-prototypes
OPT     ?= -O2 -g
SAN     := -O1 -g -fsanitize=address,undefined -fno-omit-frame-pointer -fno-sanitize-recover=all
TSANF   := -O1 -g -fsanitize=thread
LDLIBS  := -lm -lpthread
ZMQLIBS := -lzmq -lprotobuf-c -ljansson
SRVLIBS := $(ZMQLIBS) -lsqlite3
# mpmctl's VTK writer compresses with zlib (zlib1g-dev)
ZLIBS   := $(shell pkg-config --libs zlib 2>/dev/null || echo -lz)
# mpmctl's HDF5 export (clients/ctl/ctl_h5.c): Debian's serial libhdf5 (libhdf5-dev)
H5INC   := $(shell pkg-config --cflags hdf5 2>/dev/null || echo -I/usr/include/hdf5/serial)
H5LIBS  := $(shell pkg-config --libs hdf5 2>/dev/null || echo -lhdf5_serial)

MPM_SRCS   := $(wildcard solver/*.c)
PROTOS     := $(wildcard proto/*.proto)
GEN_C      := $(patsubst proto/%.proto,build/gen/%.pb-c.c,$(PROTOS))
GEN_H      := $(GEN_C:.c=.h)
MPP_SRCS   := $(wildcard protocol/*.c)
STORE_SRCS := $(wildcard server/store/*.c)
SRV_SRCS   := $(wildcard server/daemon/*.c)
CTL_SRCS   := $(wildcard clients/ctl/*.c)
CLI_SRCS   := $(wildcard clients/mpmctl/*.c)
TOOL_LIB   := $(wildcard scenes/*.c)
TEST_SRCS  := tests/runner.c tests/t_alloc.c $(wildcard tests/*/t_*.c)
# mpmtest's allocator calls go through tests/t_alloc.c's wrappers, which a
# test arms to fail the nth allocation (t_alloc.h); no other program has them
TEST_WRAP  := -Wl,--wrap=malloc,--wrap=calloc,--wrap=realloc,--wrap=aligned_alloc,--wrap=strdup,--wrap=free
BENCH_SRCS := $(wildcard bench/accuracy/*.c)
PERF_SRCS  := $(wildcard bench/perf/*.c)
# bin/mpmceiling's lean step (bench/ceiling/: also linked into mpmtest) and its program
CEIL_SRCS  := bench/ceiling/ceiling.c bench/ceiling/ceiling_avx2.c

# Include paths, per layer: the public include/ folders of the layers below.
# A file's own folder is searched first by #include "..." anyway, so a
# library's private headers need no -I of their own.
I_MPM    := -Isolver/include
I_MPP    := $(I_MPM) -Iprotocol/include
I_STORE  := $(I_MPP) -Iserver/store/include
I_SRV    := $(I_STORE) -Iserver/daemon
I_CTL    := $(I_MPP) -Iclients/ctl/include
I_SCENES := $(I_MPM) -Iscenes/include
I_BENCH  := $(I_SCENES) $(I_CTL) -Ibench
# the tests reach every layer's internals
I_TESTS  := $(I_SRV) $(I_CTL) $(I_SCENES) -Isolver -Iprotocol -Iserver/store -Ibuild/gen \
            -Itests -Itests/solver -Itests/store -Itests/daemon -Itests/clients -Ibench
INC      := $(I_TESTS)
# $(1) a build directory: each layer's objects get that layer's paths
define layer_inc
$(1)/solver/%.o: INC = $(I_MPM)
$(1)/protocol/%.o: INC = $(I_MPP) -Ibuild/gen
$(1)/gen/%.o: INC = $(I_MPP)
$(1)/server/store/%.o: INC = $(I_STORE)
$(1)/server/daemon/%.o: INC = $(I_SRV)
$(1)/server/mpmd/%.o: INC = $(I_SRV)
$(1)/clients/ctl/%.o: INC = $(I_CTL)
$(1)/clients/ctl/ctl_h5.o: INC = $(I_CTL) $(H5INC)
$(1)/clients/mpmctl/%.o: INC = $(I_CTL)
$(1)/clients/web/%.o: INC = $(I_CTL)
$(1)/scenes/%.o: INC = $(I_SCENES)
$(1)/bench/%.o: INC = $(I_BENCH)
$(1)/tests/fuzz/%.o: INC = $(I_MPP)
endef

# The AVX2+FMA kernels (solver/mpm_kernels_<unit>_avx2.c and their selection
# mpm_kernels_avx2.c, chosen at run time) on x86-64: those files with these
# flags, every file told that they exist.
ifneq ($(findstring x86_64,$(shell $(CC) -dumpmachine 2>/dev/null)),)
CSTD    += -DMPM_HAVE_AVX2_KERNELS
AVX2F   := -mavx2 -mfma -ffp-contract=fast
# Drucker-Prager's lanes (solver/mpm_plastic_avx2.c): AVX2 without
# fused multiply-adds, the scalar update's bits; -O3 fully unrolls the small
# fixed-count loops over the lanes and a stress's six components (the same
# bits; docs/performance.md)
PLASF   := -mavx2 -ffp-contract=off -O3
endif

# Builds: release (build/rel, bin/), sanitizers (build/asan), ThreadSanitizer
# (build/tsan), the lean solver for the feature-cost bench (build/lean), and
# gcov's (build/cov, make coverage).
REL  := build/rel
ASAN := build/asan
TSAN := build/tsan
LEAN := build/lean
COV  := build/cov
# atomic counters: the solver's team, the store's writer and the daemon's
# workers run the same lines at once
COVF := -O1 -g --coverage -fprofile-update=atomic
# libFuzzer (tests/fuzz/): clang's fuzzer + ASan + UBSan, objects in build/fuzz
FUZZ := build/fuzz
FUZZ_CC ?= clang
FUZZ_O ?= -O1
FUZZF = $(FUZZ_O) -g -fsanitize=fuzzer-no-link,address,undefined -fno-omit-frame-pointer \
         -fno-sanitize-recover=all

.PHONY: all deps test layers test-quick tsan bench bench-build bench-compare bench-inproc inproc-objs bench-accuracy bench-vtk bench-ceiling stress \
        demo docs-picture clean \
        format format-check lint fuzz fuzz-quick fuzz-build fuzz-seed
.SECONDARY: $(GEN_C) $(GEN_H)
all: bin/mpmd bin/mpmctl bin/mpmtest bin/mpmrun

# deploy/install-deps.sh's group: test, unless the goal sets another
# (demo, bench: below)
DEPS_GROUP ?= test
deps:
	@bash deploy/install-deps.sh $(DEPS_GROUP)
bench bench-build bench-accuracy bench-vtk bench-ceiling: DEPS_GROUP = bench

# ---- generated protobuf code --------------------------------------------------
build/gen/%.pb-c.c build/gen/%.pb-c.h: proto/%.proto
	@mkdir -p build/gen
	protoc-c --proto_path=proto --c_out=build/gen $<

# ---- objects and libraries, per build -----------------------------------------
# $(1) build dir, $(2) flags.  Every object waits for the generated header
# (order-only), then follows its own -MMD dependencies.
define build_rules
$(1)/%.o: %.c | $(GEN_H)
	@mkdir -p $$(dir $$@)
	$$(CC) $$(CSTD) $$(WARN) $(2) $$(XFLAGS) $$(INC) -MMD -MP -c $$< -o $$@
$(1)/gen/%.o: build/gen/%.c $(GEN_H)
	@mkdir -p $$(dir $$@)
	$$(CC) $$(CSTD) $(2) $$(INC) -MMD -MP -c $$< -o $$@
$(1)/libmpm.a: $(1)/.sources $(patsubst %.c,$(1)/%.o,$(MPM_SRCS))
	rm -f $$@ && $$(AR) rcs $$@ $$(filter %.o,$$^)
$(1)/libmpp.a: $(1)/.sources $(patsubst %.c,$(1)/%.o,$(MPP_SRCS)) $(patsubst build/gen/%.c,$(1)/gen/%.o,$(GEN_C))
	rm -f $$@ && $$(AR) rcs $$@ $$(filter %.o,$$^)
$(1)/libstore.a: $(1)/.sources $(patsubst %.c,$(1)/%.o,$(STORE_SRCS))
	rm -f $$@ && $$(AR) rcs $$@ $$(filter %.o,$$^)
$(1)/libsrv.a: $(1)/.sources $(patsubst %.c,$(1)/%.o,$(SRV_SRCS))
	rm -f $$@ && $$(AR) rcs $$@ $$(filter %.o,$$^)
$(1)/libscenes.a: $(1)/.sources $(patsubst %.c,$(1)/%.o,$(TOOL_LIB))
	rm -f $$@ && $$(AR) rcs $$@ $$(filter %.o,$$^)
$(1)/libctl.a: $(1)/.sources $(patsubst %.c,$(1)/%.o,$(CTL_SRCS))
	rm -f $$@ && $$(AR) rcs $$@ $$(filter %.o,$$^)
$(call layer_inc,$(1))
endef
# A library depends on the list of sources of its build, rewritten only when
# a file appears or goes, so a deleted source leaves no stale archive member.
ALL_LIB_SRCS := $(sort $(MPM_SRCS) $(MPP_SRCS) $(STORE_SRCS) $(SRV_SRCS) $(CTL_SRCS) $(TOOL_LIB))
define srclist
$(shell mkdir -p $(1); [ "$$(cat $(1)/.sources 2>/dev/null)" = "$(ALL_LIB_SRCS)" ] || echo "$(ALL_LIB_SRCS)" > $(1)/.sources)
endef
$(foreach b,$(REL) $(ASAN) $(TSAN) $(LEAN) $(FUZZ) $(COV),$(call srclist,$(b)))
$(eval $(call build_rules,$(REL),$(OPT)))
$(eval $(call build_rules,$(ASAN),$(SAN)))
$(eval $(call build_rules,$(TSAN),$(TSANF)))
$(eval $(call build_rules,$(LEAN),$(OPT) -DMPM_LEAN))
$(eval $(call build_rules,$(FUZZ),$$(FUZZF)))
$(eval $(call build_rules,$(COV),$(COVF)))
$(FUZZ)/%.o: CC := $(FUZZ_CC)
# the fuzzers reach only the solver's case check: the solver is built at
# -O0, its kernels (never called by a target) without instrumentation
$(FUZZ)/solver/%.o: FUZZ_O := -O0
$(FUZZ)/solver/mpm_kernels.o $(FUZZ)/solver/mpm_kernels_%.o: FUZZF = -O0 -g
$(foreach b,$(REL) $(ASAN) $(TSAN) $(LEAN) $(FUZZ) $(COV),$(b)/solver/mpm_kernels_avx2.o \
  $(b)/solver/mpm_kernels_%_avx2.o): XFLAGS = $(AVX2F)
$(foreach b,$(REL) $(ASAN) $(TSAN) $(LEAN) $(FUZZ) $(COV),$(b)/solver/mpm_plastic_avx2.o): XFLAGS = $(PLASF)
$(foreach b,$(REL) $(ASAN) $(TSAN) $(COV),$(b)/bench/ceiling/ceiling_avx2.o): XFLAGS = $(AVX2F)
-include $(shell find build -name '*.d' 2>/dev/null)

# Link lines, per build: $(1) build dir.  Libraries go above what they use.
mpmd_deps    = $(1)/server/mpmd/main.o $(1)/libsrv.a $(1)/libstore.a $(1)/libmpp.a $(1)/libmpm.a
mpmctl_deps  = $(patsubst %.c,$(1)/%.o,$(CLI_SRCS)) $(1)/libctl.a $(1)/libmpp.a $(1)/libmpm.a
mpmtest_deps = $(patsubst %.c,$(1)/%.o,$(TEST_SRCS) $(CEIL_SRCS)) $(1)/libscenes.a $(1)/libsrv.a \
               $(1)/libstore.a $(1)/libmpp.a $(1)/libmpm.a

# ---- the daemon, the client and the test runner --------------------------------
bin/mpmd: $(call mpmd_deps,$(REL))
	@mkdir -p bin
	$(CC) $(OPT) -o $@ $^ $(SRVLIBS) $(LDLIBS)
bin/mpmctl: $(call mpmctl_deps,$(REL))
	@mkdir -p bin
	$(CC) $(OPT) -o $@ $^ $(ZMQLIBS) $(ZLIBS) $(H5LIBS) $(LDLIBS)
bin/mpmtest: $(call mpmtest_deps,$(REL))
	@mkdir -p bin
	$(CC) $(OPT) -o $@ $^ $(TEST_WRAP) $(SRVLIBS) $(LDLIBS)
bin/mpmrun: $(REL)/scenes/mpmrun/mpmrun.o $(REL)/libscenes.a $(REL)/libmpm.a
	@mkdir -p bin
	$(CC) $(OPT) -o $@ $^ $(LDLIBS)

$(ASAN)/mpmd: $(call mpmd_deps,$(ASAN))
	$(CC) $(SAN) -o $@ $^ $(SRVLIBS) $(LDLIBS)
$(ASAN)/mpmctl: $(call mpmctl_deps,$(ASAN))
	$(CC) $(SAN) -o $@ $^ $(ZMQLIBS) $(ZLIBS) $(H5LIBS) $(LDLIBS)
$(ASAN)/mpmtest: $(call mpmtest_deps,$(ASAN))
	$(CC) $(SAN) -o $@ $^ $(TEST_WRAP) $(SRVLIBS) $(LDLIBS)

$(TSAN)/mpmd: $(call mpmd_deps,$(TSAN))
	$(CC) $(TSANF) -o $@ $^ $(SRVLIBS) $(LDLIBS)
$(TSAN)/mpmctl: $(call mpmctl_deps,$(TSAN))
	$(CC) $(TSANF) -o $@ $^ $(ZMQLIBS) $(ZLIBS) $(H5LIBS) $(LDLIBS)
$(TSAN)/mpmtest: $(call mpmtest_deps,$(TSAN))
	$(CC) $(TSANF) -o $@ $^ $(TEST_WRAP) $(SRVLIBS) $(LDLIBS)

# ---- tests ----------------------------------------------------------------------
# make test: every test under ASan+UBSan, then (without T) the fuzz targets'
# quick form (make fuzz-quick).  T=name runs one test.  Tests that
# need the daemon and the client find them through MPMD_BIN and MPMCTL_BIN.
test: deps
	@$(MAKE) --no-print-directory $(ASAN)/mpmtest $(ASAN)/mpmd $(ASAN)/mpmctl $(ASAN)/mpmweb layers
	ASAN_OPTIONS=detect_leaks=1:abort_on_error=1 UBSAN_OPTIONS=print_stacktrace=1 \
	  MPMD_BIN=$(ASAN)/mpmd MPMCTL_BIN=$(ASAN)/mpmctl $(ASAN)/mpmtest $(T)
	@if [ -z "$(T)" ]; then $(MAKE) --no-print-directory fuzz-quick; fi

# make layers (run by make test): each library's graph of its files (calls
# from the objects' symbols, includes) and its cycles; a cycle fails in the
# libraries tests/include_graph.py lists in CHECKED.  V=1 prints the graphs.
layers: $(foreach l,mpm mpp store srv ctl scenes,$(ASAN)/lib$(l).a)
	/usr/bin/python3 tests/include_graph.py --build $(ASAN) $(if $(V),,--quiet)

# The benchmarks' binaries, built (not run) in CI so that they never rot.
bench-build: deps
	@$(MAKE) --no-print-directory bin/mpmbench bin/mpmbench-lean bin/mpmbench-accuracy bin/mpmvtkbench \
	  bin/mpmceiling
	@bash bench/perf/inproc/inproc.sh --self-check
	bin/mpmceiling --check

# Release build, no sanitizers: quick local iteration.
test-quick: bin/mpmtest bin/mpmd bin/mpmctl
	MPMD_BIN=bin/mpmd MPMCTL_BIN=bin/mpmctl bin/mpmtest $(T)

# make tsan: the threaded tests (solver team, worker pool, store writer and
# readers, the daemon) under ThreadSanitizer.  TSAN_T selects them.
# tests/tsan.supp lists what TSan cannot see into (uninstrumented libraries
# only).  gcc 12's TSan stops with "unexpected memory mapping" on kernels
# with more ASLR bits (vm.mmap_rnd_bits > 28); the tests then run with ASLR
# off for them (setarch -R, inherited by the mpmd they start).
TSAN_T ?= perf_ inv_thread store_ daemon_ cpdi_two cpdi_active apic_step cond_two material_plastic triaxial_threads ckpt_same_bits_2d ckpt_threads fuse_ team_
TSAN_ENV = TSAN_OPTIONS="halt_on_error=1 second_deadlock_stack=1 suppressions=$(CURDIR)/tests/tsan.supp"
tsan: deps
	@$(MAKE) --no-print-directory $(TSAN)/mpmtest $(TSAN)/mpmd $(TSAN)/mpmctl $(TSAN)/mpmweb
	@run=""; \
	if ! $(TSAN_ENV) $(TSAN)/mpmtest --list >/dev/null 2>&1; then \
	  run="setarch $$(uname -m) -R"; \
	  echo "tsan: ThreadSanitizer cannot start with this kernel's ASLR; running under $$run"; \
	fi; \
	echo "$(TSAN_ENV) MPMD_BIN=$(TSAN)/mpmd MPMCTL_BIN=$(TSAN)/mpmctl $$run $(TSAN)/mpmtest $(TSAN_T)"; \
	$(TSAN_ENV) MPMD_BIN=$(TSAN)/mpmd MPMCTL_BIN=$(TSAN)/mpmctl $$run $(TSAN)/mpmtest $(TSAN_T)

clean:
	rm -rf build bin

# ---- formatting: make format, make format-check ------------------------------------
# .clang-format describes the style, for Debian 12's clang-format (14; another
# version may lay some lines out differently).  format rewrites the files in
# place; format-check (run by .ci/run) changes nothing and fails listing the
# files that differ.  Generated code (build/) is not ours to format.
CLANG_FORMAT ?= clang-format
SRC_DIRS := solver protocol server clients scenes bench tests
FMT_SRCS = $(shell find $(SRC_DIRS) -name '*.[ch]' -o -name '*.inc' | sort)

format: deps
	$(CLANG_FORMAT) -i $(FMT_SRCS)

format-check: deps
	@bad=0; for f in $(FMT_SRCS); do \
	  $(CLANG_FORMAT) --dry-run --Werror "$$f" >/dev/null 2>&1 && continue; \
	  n=$$($(CLANG_FORMAT) "$$f" | diff "$$f" - | grep -c '^>') || true; \
	  [ $$bad = 0 ] && echo "format-check: these files differ from .clang-format (make format fixes them):"; \
	  bad=$$((bad + 1)); echo "  $$f ($$n lines to change)"; \
	done; \
	if [ $$bad != 0 ]; then echo "format-check: FAILED, $$bad file(s)"; exit 1; fi; \
	echo "format-check: ok"

# ---- static analysis: make lint -----------------------------------------------------
# cppcheck, then gcc's -fanalyzer on every project .c (not the generated code),
# both failing on any finding.  A false positive gets a narrow inline
# suppression with its reason, or a line with its reason in tests/cppcheck.supp.
# cppcheck reads no system header, so it is told the protobuf-c version the
# generated header checks for; it checks every #if configuration of each file.
CPPCHECK ?= cppcheck
CPPCHECK_FLAGS := --enable=warning,performance,portability --std=c11 --max-configs=12 \
  --error-exitcode=1 --inline-suppr --suppressions-list=tests/cppcheck.supp -q \
  -D_POSIX_C_SOURCE=200809L -D_DEFAULT_SOURCE -DPROTOBUF_C_VERSION_NUMBER=1004001 \
  --cppcheck-build-dir=build/cppcheck -j2 $(addprefix -i ,$(wildcard solver/mpm_kernels*_avx2.c))
# (the AVX2 units are the portable ones again with other flags: both tools
# read them there)
# -fanalyzer (gcc only) at -O0, its objects in build/analyze.  Turned off:
#  -Wanalyzer-use-of-uninitialized-value: gcc 12's first version of it cannot
#    relate a loop bound to the part of an array that was filled (w[d] for
#    d < D in the solver's kernels, v[d] for d < dim), nor values from libc
#    (strtod), so its reports here are false; -Wmaybe-uninitialized and
#    cppcheck's uninitvar check the same.
#  -Wformat-truncation (not an analyzer check): at -O0 it lacks the value
#    ranges it needs; the optimised builds check it.
#  in tests/ only, -Wanalyzer-malloc-leak and -file-leak: CHECK() returns from
#    a failed test without freeing what the test allocated, by design; the
#    passing paths are checked for leaks by ASan in make test.
ANALYZER_CC ?= gcc
ANALYZE := build/analyze
ANAF := -O0 -g -fanalyzer -Wno-analyzer-use-of-uninitialized-value -Wno-format-truncation
$(ANALYZE)/tests/%.o: ANAF += -Wno-analyzer-malloc-leak -Wno-analyzer-file-leak
LINT_SRCS = $(filter-out solver/mpm_kernels%_avx2.c,$(MPM_SRCS)) $(MPP_SRCS) $(STORE_SRCS) $(SRV_SRCS) \
            server/mpmd/main.c $(CTL_SRCS) $(CLI_SRCS) $(TOOL_LIB) scenes/mpmrun/mpmrun.c $(TEST_SRCS) $(BENCH_SRCS) $(PERF_SRCS) $(wildcard bench/perf/inproc/*.c) \
            $(wildcard bench/ceiling/*.c)
$(eval $(call layer_inc,$(ANALYZE)))
$(ANALYZE)/%.o: %.c | $(GEN_H)
	@mkdir -p $(dir $@)
	$(ANALYZER_CC) $(CSTD) $(WARN) $(ANAF) $(INC) -MMD -MP -c $< -o $@

# Both run to the end (make -k), so one pass shows every finding.
lint: deps | $(GEN_H)
	@mkdir -p build/cppcheck
	@rc=0; \
	echo "$(CPPCHECK) $(CPPCHECK_FLAGS) $(INC) $(SRC_DIRS)"; \
	$(CPPCHECK) $(CPPCHECK_FLAGS) $(INC) $(SRC_DIRS) || rc=1; \
	$(MAKE) --no-print-directory -k $(patsubst %.c,$(ANALYZE)/%.o,$(LINT_SRCS)) || rc=1; \
	if [ $$rc != 0 ]; then echo "lint: FAILED (findings above)"; exit 1; fi; \
	echo "lint: ok (cppcheck, gcc -fanalyzer)"

# ---- the accuracy benchmark and the stability suite -----------------------------
# make bench-accuracy  runs bin/mpmbench-accuracy (bench/accuracy/): method, update,
#                      transfer, cells, particles per cell and dt/CFL swept on problems with
#                      known answers; table on the terminal, build/bench/accuracy.csv,
#                      and build/bench/accuracy_{time,space,dt}.png when gnuplot is
#                      there (installed through `deploy/install-deps.sh bench`).
#                      BENCH_ARGS=--quick for a short run (--help for the rest).
# make stress          the full stability suite (the stress_* tests with
#                      MPM_STRESS=full) and the reliability suite (rel_* at full
#                      size, make fuzz) on the release build, ending with the
#                      Reliability table; `make test` runs their quick form.
bin/mpmbench-accuracy: $(patsubst %.c,$(REL)/%.o,$(BENCH_SRCS)) $(REL)/libscenes.a $(REL)/libmpm.a
	@mkdir -p bin
	$(CC) $(OPT) -o $@ $^ $(LDLIBS)

bench-accuracy: deps
	@bash deploy/install-deps.sh bench || echo "bench-accuracy: could not install gnuplot-nox; the plots will be skipped"
	@$(MAKE) --no-print-directory bin/mpmbench-accuracy
	bin/mpmbench-accuracy $(BENCH_ARGS)
	@if command -v gnuplot >/dev/null 2>&1; then \
	  gnuplot build/bench/accuracy.gp && echo "plots: build/bench/accuracy_time.png accuracy_space.png accuracy_dt.png"; \
	else echo "bench-accuracy: gnuplot not found, plots skipped (bash deploy/install-deps.sh bench installs it)"; fi

# The reliability part: the rel_* tests (kill -9, load, watchers, disk,
# hostile input; tests/daemon/t_reliab_*.c) at full size and `make fuzz`; their
# "reliability:" lines are gathered into docs/reliability.md's table
# (tests/reliab_table.sh) at the end.  Every part runs even if one fails.
STRESS_LOG := build/stress.log
stress: deps
	@$(MAKE) --no-print-directory bin/mpmtest bin/mpmd bin/mpmctl
	@mkdir -p build && rm -f $(STRESS_LOG) build/stress.rc
	@{ MPM_STRESS=full MPMD_BIN=bin/mpmd MPMCTL_BIN=bin/mpmctl bin/mpmtest stress_ rel_ 2>&1; \
	   echo $$? > build/stress.rc; } | tee $(STRESS_LOG)
	@{ $(MAKE) --no-print-directory fuzz 2>&1; echo $$? >> build/stress.rc; } | tee -a $(STRESS_LOG)
	@bash tests/reliab_table.sh $(STRESS_LOG)
	@! grep -qv '^0$$' build/stress.rc || { echo "stress: FAILED (see $(STRESS_LOG))"; exit 1; }

# ---- fuzzing: make fuzz, make fuzz-quick -------------------------------------------
# libFuzzer targets (tests/fuzz/fuzz_<target>.c), built with clang into
# build/fuzz with the protocol and solver libraries compiled there too:
#   request  the daemon's request path (decode, case check, the reply)
#   case     packed Case bytes -> the case codec -> mpm_case_check
#   json     JSON case text -> the JSON mapping -> mpm_case_check
#   stream   the stream and reply decoders the clients use
# Each starts from its corpus, tests/fuzz/corpus/<target>/ (kept small:
# seeds from proto/examples and from encoded messages of every kind,
# minimised with -merge=1; `make fuzz-seed` renews it).
# make fuzz        FUZZ_RUNS executions per target (4 x 260000 >= 10^6), at most
#                  FUZZ_TIME s each; a table; fails on any crash or sanitizer report
# make fuzz-quick  every target over its corpus plus FUZZ_QUICK_RUNS mutations
#                  (run by make test)
FUZZ_TARGETS    := request case json stream
FUZZ_BINS       := $(patsubst %,$(FUZZ)/fuzz_%,$(FUZZ_TARGETS))
FUZZ_RUNS       ?= 260000
FUZZ_TIME       ?= 900
FUZZ_QUICK_RUNS ?= 20000
$(FUZZ)/fuzz_%: $(FUZZ)/tests/fuzz/fuzz_%.o $(FUZZ)/libmpp.a $(FUZZ)/libmpm.a
	$(FUZZ_CC) $(FUZZF) -fsanitize=fuzzer -o $@ $^ -lprotobuf-c -ljansson $(LDLIBS)
$(FUZZ)/fuzz_seed: $(REL)/tests/fuzz/fuzz_seed.o $(REL)/libmpp.a $(REL)/libmpm.a
	$(CC) $(OPT) -o $@ $^ -lprotobuf-c -ljansson $(LDLIBS)

fuzz-build: deps
	@$(MAKE) --no-print-directory $(FUZZ_BINS)

fuzz: fuzz-build
	bash tests/fuzz/run.sh $(FUZZ_RUNS) $(FUZZ_TIME) $(FUZZ_TARGETS)

fuzz-quick: fuzz-build
	bash tests/fuzz/run.sh $(FUZZ_QUICK_RUNS) 60 $(FUZZ_TARGETS)

# Renews the corpora: the seeds, merged (-merge=1) with what is there.
fuzz-seed: fuzz-build
	@$(MAKE) --no-print-directory $(FUZZ)/fuzz_seed
	rm -rf $(FUZZ)/seeds && $(FUZZ)/fuzz_seed $(FUZZ)/seeds proto/examples/*.json
	@for t in $(FUZZ_TARGETS); do \
	  mkdir -p tests/fuzz/corpus/$$t $(FUZZ)/work/$$t && \
	  $(FUZZ)/fuzz_$$t -merge=1 tests/fuzz/corpus/$$t $(FUZZ)/seeds/$$t $(FUZZ)/work/$$t \
	    >$(FUZZ)/merge_$$t.log 2>&1 || { cat $(FUZZ)/merge_$$t.log; exit 1; }; \
	  echo "fuzz-seed: $$t: $$(ls tests/fuzz/corpus/$$t | wc -l) files"; \
	done

# ---- the throughput benchmark ----------------------------------------------------
# make bench  runs bin/mpmbench --all (bench/perf/): disks2d, cube3d and bar1d at
#             ~10^6 particles and sparse2d, MPM and GIMP, 1 and 2 threads;
#             disks2d against bin/mpmbench-lean (the same sources on a solver
#             compiled with -DMPM_LEAN, objects in build/lean); disks2d through a
#             real bin/mpmd.  Table on the terminal, rows appended to
#             build/bench/throughput.csv.  One scene: bin/mpmbench --scene NAME.
bin/mpmbench: $(patsubst %.c,$(REL)/%.o,$(PERF_SRCS)) $(REL)/libscenes.a $(REL)/libmpp.a $(REL)/libmpm.a
	@mkdir -p bin
	$(CC) $(OPT) -o $@ $^ $(ZMQLIBS) $(LDLIBS)
# the lean binary has no daemon scene, so it needs only the solver
bin/mpmbench-lean: $(patsubst %.c,$(LEAN)/%.o,$(PERF_SRCS)) $(LEAN)/libscenes.a $(LEAN)/libmpm.a
	@mkdir -p bin
	$(CC) $(OPT) -o $@ $^ $(LDLIBS)

# make bench-vtk  the VTK writer of mpmctl: a synthetic 10^6-particle snapshot
#                 written as .vtp in each encoding, file sizes and write times
#                 (BENCH_ARGS: --n N, --dim 3, --all, --skip-ascii; --help).
bin/mpmvtkbench: $(REL)/bench/vtk/mpmvtkbench.o $(REL)/libctl.a $(REL)/libmpp.a $(REL)/libmpm.a
	@mkdir -p bin
	$(CC) $(OPT) -o $@ $^ $(ZMQLIBS) $(ZLIBS) $(LDLIBS)

bench-vtk: deps
	@$(MAKE) --no-print-directory bin/mpmvtkbench
	bin/mpmvtkbench $(BENCH_ARGS)

# make bench-ceiling  the solver's ceiling: bin/mpmceiling (bench/ceiling/: the
#             disks2d scene's 2D MPM USF step with nothing but its arithmetic,
#             four lanes where the CPU has AVX2 and FMA) against bin/mpmbench's
#             disks2d MPM USF on 1 thread, alternated (CEILING_ROUNDS, default 3),
#             at 10^4 and 10^6 particles, with the triad: what a step of the
#             solver's design can reach here, and what the solver reaches.
bin/mpmceiling: $(REL)/bench/ceiling/mpmceiling.o $(patsubst %.c,$(REL)/%.o,$(CEIL_SRCS))
	@mkdir -p bin
	$(CC) $(OPT) -o $@ $^ $(LDLIBS)

bench-ceiling: deps
	@$(MAKE) --no-print-directory bin/mpmceiling bin/mpmbench
	@bash bench/ceiling/ceiling.sh

bench: deps
	@$(MAKE) --no-print-directory bin/mpmbench bin/mpmbench-lean bin/mpmd
	bin/mpmbench --all
	@echo "bench: rows appended to build/bench/throughput.csv"

# make bench-compare REF=<commit>  this tree's bin/mpmbench against REF's, on
#             the same machine, interleaved (bench/perf/compare.sh): REF is
#             checked out as a git worktree in build/compare/<short-sha> and its
#             bench built there with its own Makefile; then COMPARE_ROUNDS (3)
#             rounds of a triad (bin/mpmbench --triad) and every configuration,
#             before then after; a table of the medians, after / before, the
#             range of the rounds' own ratios (~: it straddles 1) and after's
#             fraction of the triad roof.  Default: disks2d and cube3d,
#             10^6 particles, MPM / GIMP / BSPLINE2 (USF, MUSL, MUSL APIC) and
#             MPM USL on 2 threads, MPM USF on 1, the collapse2d elastic and
#             Drucker-Prager pair (~25 min).  COMPARE_QUICK=1: a short sanity
#             run; COMPARE_ARGS, COMPARE_PARTICLES, COMPARE_STEPS, COMPARE_RUN_S:
#             see the script's head.
bench-compare:
	@test -n "$(REF)" || { echo "usage: make bench-compare REF=<commit> [COMPARE_QUICK=1]" >&2; exit 2; }
	@bash bench/perf/compare.sh $(REF)

# make bench-inproc REF=<commit>  this tree's solver against REF's in one
#             process, alternated round by round (bench/perf/inproc/): REF's
#             tree and bench as for bench-compare, REF's solver linked into the
#             driver with its symbols made local; for each configuration
#             INPROC_PROCS (3) processes, each with both simulations resident,
#             a warm-up, then INPROC_ROUNDS (7) rounds,
#             REF first in even rounds, this tree first in odd; a table of each
#             side's median, the median of the rounds' own ratios, quartiles,
#             extremes and the rounds won.  Default: bench-compare's
#             configurations but collapse2d (~6 min).  INPROC_ARGS,
#             INPROC_PARTICLES, INPROC_RUN_S: see the script's head.
INPROC_OBJS := $(REL)/bench/perf/inproc/inproc.o $(REL)/bench/perf/inproc/side.o $(REL)/bench/perf/triad.o
inproc-objs: $(INPROC_OBJS) $(REL)/libscenes.a $(REL)/libmpm.a
bench-inproc:
	@test -n "$(REF)" || { echo "usage: make bench-inproc REF=<commit>" >&2; exit 2; }
	@bash bench/perf/inproc/inproc.sh $(REF)

# ---- the demo ----------------------------------------------------------------------
# make demo: installs the demo group only (deploy/install-deps.sh demo),
# builds mpmd, mpmctl and mpmweb, then deploy/demo.sh: mpmd and the web
# monitor on loopback with the default database, a granular column collapse
# (20-30 s, snapshots recorded) watched live, the commands to try next.
# make demo CASE=disks: the paper's bouncing disks instead.
CASE ?= collapse
demo: DEPS_GROUP = demo
demo: deps
	@$(MAKE) --no-print-directory bin/mpmd bin/mpmctl bin/mpmweb
	bash deploy/demo.sh $(CASE)

# make docs-picture: the README's picture, docs/web_monitor.png, taken again:
# the demo's case run to its end in a database of its own, then the monitor
# showing its recorded step 3500 (mid-collapse) in headless Chromium.
docs-picture: deps
	@$(MAKE) --no-print-directory bin/mpmd bin/mpmctl bin/mpmweb
	rm -rf build/picture.db*
	MPMD_DB=build/picture.db MPMD_ENDPOINT=$${MPMD_ENDPOINT:-tcp://127.0.0.1:5575} \
	  MPMWEB_LISTEN=$${MPMWEB_LISTEN:-127.0.0.1:8085} DEMO_PAUSE=0 \
	  DEMO_PICTURE=docs/web_monitor.png bash deploy/demo.sh collapse < /dev/null

# ---- mpmweb, the live web monitor (clients/web/) -----------------------------------
# bin/mpmweb: the gateway (clients/web/*.c) with mpmctl's connection, keys and
# JSON helpers, the protocol library and libmicrohttpd; its page is
# clients/web/static/ (read at run time, found beside the binary).  The tests
# find it through MPMWEB_BIN (else beside MPMD_BIN); the web_ tests drive it
# with headless Chromium.
WEB_SRCS := $(wildcard clients/web/*.c)
WEBLIBS  := -lmicrohttpd $(ZMQLIBS) $(LDLIBS)
mpmweb_deps = $(patsubst %.c,$(1)/%.o,$(WEB_SRCS)) $(1)/libctl.a $(1)/libmpp.a $(1)/libmpm.a
LINT_SRCS += $(WEB_SRCS)
all: bin/mpmweb
bin/mpmweb: $(call mpmweb_deps,$(REL))
	@mkdir -p bin
	$(CC) $(OPT) -o $@ $^ $(WEBLIBS)
$(ASAN)/mpmweb: $(call mpmweb_deps,$(ASAN))
	$(CC) $(SAN) -o $@ $^ $(WEBLIBS)
$(TSAN)/mpmweb: $(call mpmweb_deps,$(TSAN))
	$(CC) $(TSANF) -o $@ $^ $(WEBLIBS)
test-quick: bin/mpmweb
test-quick: export MPMWEB_BIN = bin/mpmweb
test: export MPMWEB_BIN = $(ASAN)/mpmweb
tsan: export MPMWEB_BIN = $(TSAN)/mpmweb
TSAN_T += web_
# ---- the Python client (clients/python) -----------------------------------------
# make python: the protobuf classes of proto/mpmd.proto for the `mpmd` package
# (clients/python/mpmd), generated by protoc into build/python/mpmd_pb2.py, never
# committed.  Use it with Debian's interpreter:
#   PYTHONPATH=clients/python:build/python /usr/bin/python3 -c 'import mpmd'
# make python-install PYTHON_DEST=DIR copies the package, with its mpmd_pb2,
# into DIR/mpmd (e.g. DIR = ~/.local/lib/python3.11/site-packages).
# The test (tests/clients/t_python_client.c) generates its own copy with the same command.
PY_GEN := build/python/mpmd_pb2.py
.PHONY: python python-install coverage
all: python
python: $(PY_GEN)
$(PY_GEN): proto/mpmd.proto
	@mkdir -p build/python
	protoc --proto_path=proto --python_out=build/python $<
python-install: $(PY_GEN)
	@test -n "$(PYTHON_DEST)" || { echo "python-install: give PYTHON_DEST=DIR"; exit 1; }
	mkdir -p "$(PYTHON_DEST)/mpmd"
	cp clients/python/mpmd/*.py $(PY_GEN) "$(PYTHON_DEST)/mpmd/"

# ---- coverage: make coverage ---------------------------------------------------------
# make coverage  the tests (all, or T=...) on gcov's build (gcc --coverage, objects
#                in build/cov; the mpmd, mpmctl and mpmweb the tests start are
#                built there too, so the daemon's and the clients' lines count),
#                then line coverage per library and in total (tests/coverage.py,
#                over gcovr: `deploy/install-deps.sh coverage`); gcovr's table of
#                every file in build/cov/coverage.txt.  Counts start from zero
#                each time.  Not part of make test; the figures are in
#                docs/architecture.md, "Testing".
$(COV)/mpmd: $(call mpmd_deps,$(COV))
	$(CC) $(COVF) -o $@ $^ $(SRVLIBS) $(LDLIBS)
$(COV)/mpmctl: $(call mpmctl_deps,$(COV))
	$(CC) $(COVF) -o $@ $^ $(ZMQLIBS) $(ZLIBS) $(H5LIBS) $(LDLIBS)
$(COV)/mpmtest: $(call mpmtest_deps,$(COV))
	$(CC) $(COVF) -o $@ $^ $(TEST_WRAP) $(SRVLIBS) $(LDLIBS)
$(COV)/mpmweb: $(call mpmweb_deps,$(COV))
	$(CC) $(COVF) -o $@ $^ $(WEBLIBS)

coverage: deps
	@bash deploy/install-deps.sh coverage
	@$(MAKE) --no-print-directory $(COV)/mpmtest $(COV)/mpmd $(COV)/mpmctl $(COV)/mpmweb
	@find $(COV) -name '*.gcda' -delete
	@rc=0; MPMD_BIN=$(COV)/mpmd MPMCTL_BIN=$(COV)/mpmctl MPMWEB_BIN=$(COV)/mpmweb \
	  $(COV)/mpmtest $(T) || rc=$$?; \
	/usr/bin/python3 tests/coverage.py $(COV) || rc=1; \
	if [ $$rc != 0 ]; then echo "coverage: some tests failed (the figures count what ran)"; exit 1; fi
