#!/usr/bin/env bash
# One-frame costs as a user meets them, in fresh processes: an empty-stack `libfx run`
# (default ZIP output) of two builds interleaved, its -v phases, and the first frame of
# blur, edges and bloom. Run it on a quiet machine.
#   bash tests/bench/bench_one_frame.sh OLD_CLI NEW_CLI [PASSES.exr]
set -u
cd "$(dirname "$0")/../.."
old=${1:?usage: bench_one_frame.sh OLD_CLI NEW_CLI [PASSES.exr]} new=${2:?}
P=${3:-out/bench_live/renders/greek_bath_1920x1080/r_libfx_passes.0001.exr}
t=$(mktemp -d); trap 'rm -rf "$t"' EXIT
echo '{"version":1,"effects":[]}' >"$t/empty.json"
echo '{"version":1,"effects":[{"effect":"gaussian_blur","params":{"sigma":16.667}}]}' >"$t/blur.json"
echo '{"version":1,"effects":[{"effect":"edges"}]}' >"$t/edges.json"
for q in draft final; do echo "{\"version\":1,\"quality\":\"$q\",\"effects\":[{\"effect\":\"bloom\"}]}" >"$t/bloom_$q.json"; done
echo "== load: $(uptime)"
echo "== one-frame empty stack, default output (zip), 9 runs interleaved: old / new wall s"
for i in $(seq 1 9); do
  for b in $old $new; do /usr/bin/time -f "$b %e" $b run --quiet --force --stack $t/empty.json $P -o $t/e.exr 2>&1 | tail -1; done
done | awk '{a[$1]=a[$1]" "$2} END{for(k in a) print k, a[k]}'
echo "== -v phases of the new build, 5 runs"
for i in 1 2 3 4 5; do $new run -v --force --stack $t/empty.json $P -o $t/e.exr | grep "read"; done
echo "== first-frame blur sigma 16.7 / edges / bloom, new build, 7 runs each (ms from -v)"
for r in $t/blur.json $t/edges.json $t/bloom_final.json $t/bloom_draft.json; do
  echo "-- $r"; for i in $(seq 1 7); do $new run -v -j 2 --force --compression none --stack $r $P -o $t/x.exr | grep -o '"ms":[0-9.]*' | head -1; done | tr '\n' ' '; echo
done
echo "== load: $(uptime)"
