#!/usr/bin/env bash
# Fuzzes geodex's parsers with AFL++ on stable Rust (cargo-afl), one target
# at a time, then minimises what each run found into fuzz/corpus/<target>/.
#
#   fuzz/run.sh [SECONDS] [TARGET...]
#
# SECONDS per target (default 600); TARGETs default to all of them.
# SECONDS=0 only minimises the queues already under fuzz/out/ again. Needs
# `cargo install cargo-afl` (which builds AFL++ on first use). Results:
# fuzz/out/<target>/ (AFL's output, not committed), a line per target in
# fuzz/out/results.tsv, and any crash or hang copied to fuzz/out/found/.
set -euo pipefail

cd "$(dirname "$0")"
seconds=${1:-600}
shift || true
all=(png jpeg tiff npy nifti obj ply off stl json_bodies)
targets=("$@")
[ ${#targets[@]} -gt 0 ] || targets=("${all[@]}")
export CARGO_TARGET_DIR=${CARGO_TARGET_DIR:-$PWD/target}
bin=$CARGO_TARGET_DIR/release
# A shared machine: AFL may not pin a core, change the CPU governor or see
# the core-dump handler; no curses screen in a log.
export AFL_SKIP_CPUFREQ=1 AFL_I_DONT_CARE_ABOUT_MISSING_CRASHES=1 AFL_NO_UI=1 \
    AFL_NO_AFFINITY=1

# afl-cmin in AFL++ 4.40c is a Python script that records no coverage for
# these persistent-mode targets ("0 unique tuples"); its awk version, next
# to it in the AFL++ that cargo-afl built for this rustc, does.
rustc_id=$(rustc -V | awk '{ print $2 "-" substr($3, 2, 7) }')
afl_bin=$(dirname "$(find "${XDG_DATA_HOME:-$HOME/.local/share}/afl.rs/rustc-$rustc_id" \
    -name afl-cmin.awk -path '*/afl/bin/*' | head -1)")

# Replaces corpus/$1 by the smallest set of its AFL queue entries with the
# same coverage, named by content, none of 64 KiB or more.
minimise() {
    local t=$1
    rm -rf "out/cmin-$t"
    PATH=$afl_bin:$PATH AFL_PATH=$afl_bin nice -n 19 "$afl_bin/afl-cmin.awk" -t 5000 \
        -i "out/$t/default/queue" -o "out/cmin-$t" -- "$bin/$t" >"out/cmin-$t.log" 2>&1
    local kept=(out/cmin-"$t"/*)
    [ -e "${kept[0]}" ] || {
        echo "afl-cmin kept nothing for $t: see fuzz/out/cmin-$t.log" >&2
        exit 1
    }
    rm -rf "corpus/$t"
    mkdir -p "corpus/$t"
    for f in "${kept[@]}"; do
        [ "$(stat -c %s "$f")" -lt 65536 ] || continue
        cp "$f" "corpus/$t/$(sha1sum <"$f" | cut -c1-16)"
    done
}

if [ "$seconds" = 0 ]; then
    for t in "${targets[@]}"; do
        minimise "$t"
        printf '%s\t%s\n' "$t" "$(ls "corpus/$t" | wc -l)"
    done
    exit 0
fi

nice -n 19 cargo afl build --release --bins
mkdir -p out/found
[ -f out/results.tsv ] ||
    printf 'target\tseconds\texecs\texecs_per_sec\tqueue\tcorpus\tcrashes\thangs\tdate\n' >out/results.tsv

for t in "${targets[@]}"; do
    echo "== $t: ${seconds}s" >&2
    rm -rf "out/$t" "out/in-$t"
    mkdir -p "out/in-$t"
    # The saved corpus and the inputs that once failed are the seeds.
    cp corpus/"$t"/* "out/in-$t/"
    if [ -d "regressions/$t" ]; then cp regressions/"$t"/* "out/in-$t/"; fi
    dict=()
    if [ -f "dict/$t.dict" ]; then dict=(-x "dict/$t.dict"); fi
    # -t: a run slower than 2 s is a hang (the real limits let a small
    # file declare a large image; decoding one takes well under that).
    nice -n 19 cargo afl fuzz -V "$seconds" -t 2000 -i "out/in-$t" -o "out/$t" \
        "${dict[@]}" -- "$bin/$t" >"out/$t.log" 2>&1 || {
        echo "afl-fuzz failed for $t: see fuzz/out/$t.log" >&2
        tail -20 "out/$t.log" >&2
        exit 1
    }
    stats=out/$t/default/fuzzer_stats
    get() { awk -F' *: *' -v k="$1" '$1 == k { print $2 }' "$stats"; }
    crashes=$(get saved_crashes)
    hangs=$(get saved_hangs)
    for kind in crashes hangs; do
        for f in out/"$t"/default/"$kind"/id*; do
            [ -e "$f" ] || continue
            cp "$f" "out/found/$t-$kind-$(sha1sum <"$f" | cut -c1-16)"
        done
    done
    minimise "$t"
    printf '%s\t%s\t%s\t%s\t%s\t%s\t%s\t%s\t%s\n' "$t" "$(get run_time)" "$(get execs_done)" \
        "$(get execs_per_sec)" "$(get corpus_count)" "$(ls "corpus/$t" | wc -l)" "$crashes" "$hangs" \
        "$(date -u +%F)" | tee -a out/results.tsv
done
