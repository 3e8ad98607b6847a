#!/usr/bin/env bash
# Builds the league's server (SimSpark + rcssserver3d) and UT Austin Villa's
# agent for naofarm's `league` trial program, into a cache outside the clone.
#
#   programs/league/build.sh [SOURCE [CACHE]]
#
# SOURCE holds simspark-*rcssserver3d-*.tar.gz and utaustinvilla3d*.tar.gz
# (as ../shared/third-party does), or those trees unpacked. Without SOURCE
# the pinned upstream sources are fetched into CACHE/sources (once; curl)
# and checked before anything is built: the repositories' archives at the
# commits below, each by the sha256 of its files (GitHub makes its archives
# on request, and their compressed bytes have changed before; the files
# have not). $NAOFARM_LEAGUE_MIRROR replaces https://github.com in their
# addresses. CACHE defaults to
# $NAOFARM_LEAGUE_CACHE, else ~/.cache/naofarm/league. The build goes into
# CACHE/<key>, where the key hashes the sources, the patches and this
# script: a second call with the same inputs builds nothing. The last line
# printed is the trial program to register with a worker:
#
#   naofarm worker --program league=CACHE/<key>/bin/league-trial
#
# Debian packages it needs (installed by .ci/run): cmake g++ make libode-dev
# libsdl1.2-dev ruby ruby-dev libdevil-dev libboost-dev libboost-thread-dev
# libboost-regex-dev libboost-system-dev libgl-dev libglu1-mesa-dev
# libfreetype-dev python3.
set -euo pipefail

here="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
# shellcheck source=programs/set-up.sh
. "$here/../set-up.sh"
fetchable=1
set_up_arguments NAOFARM_LEAGUE_CACHE league "$@"

# The pinned upstream sources: the file it is kept as, its address below
# the mirror, and the sha256 of its files (tree_digest).
upstream=(
    "simspark-0.3.2-rcssserver3d-0.7.3.tar.gz zzufootball/SIMSPARK/archive/f6934a6.tar.gz 406ee87acf57cbba6f5701e3f7551fe34aee1570b54e8888bc2e10c2c5151b8a"
    "utaustinvilla3d.tar.gz LARG/utaustinvilla3d/archive/dbb2fb3.tar.gz 5bd17ba377dabb60ee3dc0d5e57253acd347955fa998469f031a17aca27877e9"
)

# The sha256 of an archive's files: each regular file's sha256 and path
# below the archive's one top directory, in byte order.
tree_digest() {
    local t
    t="$(mktemp -d)"
    if tar -xzf "$1" -C "$t" 2>/dev/null && [[ "$(find "$t" -mindepth 1 -maxdepth 1 | wc -l)" == 1 ]]; then
        (cd "$t"/*/ && find . -type f -print0 | LC_ALL=C sort -z | xargs -0 sha256sum) |
            sha256sum | cut -d' ' -f1
    else
        echo "not a tar.gz archive of one directory"
    fi
    rm -rf "$t"
}

# Fetches the pinned sources into $cache/sources (what is there was checked
# when it was fetched) and makes that the SOURCE.
fetch_sources() {
    local mirror="${NAOFARM_LEAGUE_MIRROR:-https://github.com}" dir="$cache/sources"
    local name path digest got
    mkdir -p "$dir"
    exec 8>"$cache/.lock-sources"
    flock 8
    for entry in "${upstream[@]}"; do
        read -r name path digest <<<"$entry"
        [[ -f "$dir/$name" ]] && continue
        echo "fetching $mirror/$path"
        if ! curl -fsSL --retry 3 -o "$dir/$name.part" "$mirror/$path"; then
            rm -f "$dir/$name.part"
            echo "$0: could not fetch $mirror/$path; give the sources as SOURCE instead" >&2
            exit 1
        fi
        got="$(tree_digest "$dir/$name.part")"
        if [[ "$got" != "$digest" ]]; then
            rm -f "$dir/$name.part"
            echo "$0: $mirror/$path is not the pinned source: its files' sha256 is $got, not $digest" >&2
            exit 1
        fi
        mv "$dir/$name.part" "$dir/$name"
    done
    exec 8>&-
    source_dir="$dir"
}
[[ -n "$source_dir" ]] || fetch_sources

# One source: a tarball matching $1 or an unpacked tree matching $2.
find_source() {
    local tarball tree
    tarball="$(find "$source_dir" -maxdepth 1 -name "$1" -type f | sort | head -n 1)"
    tree="$(find "$source_dir" -maxdepth 1 -name "$2" -type d | sort | head -n 1)"
    if [[ -n "$tarball" ]]; then
        echo "$tarball"
    elif [[ -n "$tree" ]]; then
        echo "$tree"
    else
        echo "$0: no $1 nor $2 in $source_dir" >&2
        exit 1
    fi
}
spark_src="$(find_source 'simspark-*rcssserver3d-*.tar.gz' 'simspark-*rcssserver3d-*')"
ut_src="$(find_source 'utaustinvilla3d*.tar.gz' 'utaustinvilla3d*')"

# What the build is made of, for the cache key.
digest_of() {
    if [[ -f "$1" ]]; then
        sha256sum <"$1"
    else
        (cd "$1" && find . -type f ! -path './build/*' -print0 | sort -z |
            xargs -0 sha256sum) | sha256sum
    fi
}
# Raise when the build steps below change what they make.
build_steps=1
key="$({
    echo "$build_steps"
    digest_of "$spark_src"
    digest_of "$ut_src"
    cat "$here"/patches/*.patch
} | sha256sum | cut -c1-16)"
prefix="$cache/$key"
# One build of a key at a time: a second call waits for the first, then
# finds it built. A worker's program is replaced by a rename, never
# rewritten in place.
mkdir -p "$cache"
exec 9>"$cache/.lock-$key"
flock 9
# The trial program is copied on every call: it is not part of the build.
install_trial() {
    mkdir -p "$prefix/bin"
    cp "$here/league-trial" "$prefix/bin/league-trial.new"
    chmod +x "$prefix/bin/league-trial.new"
    mv "$prefix/bin/league-trial.new" "$prefix/bin/league-trial"
    echo "$prefix/bin/league-trial"
}
if [[ -f "$prefix/.built" ]]; then
    echo "league build $key is cached in $prefix"
    install_trial
    exit 0
fi

work="$cache/.work-$key"
rm -rf "$work" "$prefix"
mkdir -p "$work" "$prefix"
# A failed step names its log; the half-made build is left for a look and
# replaced by the next call.
trap 'echo "$0: the league build failed; its logs are in $work" >&2' ERR
# A source into $work/$2, whatever its top directory is called (a
# repository's archive names it after the commit).
unpack() {
    if [[ -f "$1" ]]; then
        mkdir "$work/$2.unpacked"
        tar -xzf "$1" -C "$work/$2.unpacked"
        mv "$work/$2.unpacked"/*/ "$work/$2"
        rmdir "$work/$2.unpacked"
    else
        cp -r "$1" "$work/$2"
    fi
}
unpack "$spark_src" simspark-rcssserver3d
unpack "$ut_src" utaustinvilla3d
spark_tree="$work/simspark-rcssserver3d"
ut_tree="$work/utaustinvilla3d"
patch -d "$spark_tree" -p1 --forward <"$here/patches/simspark-rcssserver3d.patch"
patch -d "$ut_tree" -p1 --forward <"$here/patches/utaustinvilla3d.patch"

jobs="$(nproc)"
echo "building SimSpark into $prefix"
cmake -S "$spark_tree/spark" -B "$spark_tree/spark/build" \
    -DCMAKE_BUILD_TYPE=Release -DBUILD_CARBON=OFF \
    -DCMAKE_INSTALL_PREFIX="$prefix" >"$work/spark-cmake.log" 2>&1
make -C "$spark_tree/spark/build" -j"$jobs" install >"$work/spark-make.log" 2>&1

echo "building rcssserver3d"
SPARK_DIR="$prefix" cmake -S "$spark_tree/rcssserver3d" \
    -B "$spark_tree/rcssserver3d/build" -DCMAKE_BUILD_TYPE=Release \
    -DCMAKE_INSTALL_PREFIX="$prefix" >"$work/server-cmake.log" 2>&1
make -C "$spark_tree/rcssserver3d/build" -j"$jobs" install >"$work/server-make.log" 2>&1

echo "building UT Austin Villa's agent"
cmake -S "$ut_tree" -B "$ut_tree/build" -DCMAKE_BUILD_TYPE=Release \
    -DRCSSNET3D_INCLUDE_DIR="$spark_tree/spark/utility" \
    -DRCSSNET3D_LIBRARY="$prefix/lib/simspark/librcssnet3D.so" \
    -DCMAKE_CXX_FLAGS="-Wall -Wno-unused -I$spark_tree/spark/lib -I$spark_tree/spark/build" \
    >"$work/agent-cmake.log" 2>&1
make -C "$ut_tree/build" -j"$jobs" >"$work/agent-make.log" 2>&1

# The agent reads ./skills/*.skl and its parameter files from where it runs.
mkdir -p "$prefix/agent/skills"
cp "$ut_tree/build/agentspark" "$prefix/agent/"
cp -r "$ut_tree/paramfiles" "$prefix/agent/"
cp "$ut_tree"/skills/*.skl "$prefix/agent/skills/"
echo "$key" >"$prefix/.built"
rm -rf "$work"
echo "league build $key is in $prefix"
install_trial
