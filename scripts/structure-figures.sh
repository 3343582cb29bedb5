#!/usr/bin/env bash
# The structure figures issue 44 asks for, from the tree as it is: how many places name a stage
# by hand, which arrows run from the shared layer (common/) up to a service, the largest source
# files and the hand-written Display impls. Run from anywhere: scripts/structure-figures.sh
# (with `duplicates` on PATH it also counts repeated-code pairs).
set -euo pipefail
cd "$(dirname "$0")/.."

files() { git ls-files -- "$@"; }
is_test() { grep -Eq '(^|/)tests?/|(^|/)tests\.rs$|/benches/|^fuzz/' <<<"$1"; }

echo "## Stage::X references outside common/"
all=0 nontest=0
while read -r f; do
    n=$(grep -Eo 'Stage::[A-Z][A-Za-z]*' "$f" | grep -vc 'Stage::ALL' || true)
    all=$((all + n))
    is_test "$f" || nontest=$((nontest + n))
done < <(files '*.rs' | grep -v '^common/')
echo "all: $all; outside test files: $nontest"

echo "## Arrows from common/ to a service (path dependencies of a common/ package on services/)"
arrows=0
while read -r manifest; do
    deps=$(grep -Eo '^[a-z0-9_-]+' "$manifest" | sort -u || true)
    for d in $deps; do
        if [ -d "services/$d" ]; then
            echo "  $manifest -> $d"
            arrows=$((arrows + 1))
        fi
    done
done < <(files 'common/*Cargo.toml' 'common/Cargo.toml')
echo "arrows: $arrows"

echo "## The 8 largest non-test source files (lines)"
files '*.rs' '*.js' '*.py' | while read -r f; do is_test "$f" || echo "$(wc -l <"$f") $f"; done |
    sort -rn | head -8

echo "## Hand-written Display impls (outside tests)"
n=0
while read -r f; do
    is_test "$f" && continue
    c=$(grep -Ec 'impl[^{]*(fmt::)?Display for' "$f" || true)
    n=$((n + c))
done < <(files '*.rs')
echo "impl Display: $n"

if command -v duplicates >/dev/null; then
    echo "## Repeated-code pairs"
    duplicates --most 200 --seconds 120 | head -1
fi
