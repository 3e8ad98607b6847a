#!/usr/bin/env bash
# Sets up naofarm's `t1` trial program: the league's 2026 server
# (rcssservermj, pinned, from the Python package registry) in a virtual
# environment, its example T1 locomotion policy, and the program itself,
# into a cache outside the clone.
#
#   programs/t1/setup.sh SOURCE [CACHE]
#
# SOURCE holds rcssservermj-nn_client-*.tar.gz (as ../shared/third-party
# does), the server's example client with the policy. CACHE defaults to
# $NAOFARM_T1_CACHE, else ~/.cache/naofarm/t1. The set-up goes into
# CACHE/<key>, where the key hashes the pins, the policy's archive, the
# patches and this folder's files: a second call with the same inputs does
# nothing but print the program. The last line printed is the trial program
# to register with a worker:
#
#   naofarm worker --program t1=CACHE/<key>/bin/t1-trial
#
# It needs python3 with its venv module and the registry (about 175 MB).
set -euo pipefail

here="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
# shellcheck source=programs/set-up.sh
. "$here/../set-up.sh"
set_up_arguments NAOFARM_T1_CACHE t1 "$@"
client="$(find "$source_dir" -maxdepth 1 -name 'rcssservermj-nn_client-*.tar.gz' -type f | sort | head -n 1)"
[[ -n "$client" ]] || {
    echo "$0: no rcssservermj-nn_client-*.tar.gz in $source_dir" >&2
    exit 1
}
# The server and its numerics, pinned.
pins=(rcsssmj==0.2.1 mujoco==3.5.0 numpy==2.4.6)
key="$({
    printf '%s\n' "${pins[@]}"
    sha256sum <"$client"
    cat "$here"/patches/*.patch "$here/t1-trial" "$here/server.py" "$here/policy.py" "$here/setup.sh"
} | sha256sum | cut -c1-16)"
prefix="$cache/$key"
mkdir -p "$cache"
# One set-up of a key at a time; the program is installed by a rename.
exec 9>"$cache/.lock-$key"
flock 9
if [[ -f "$prefix/.built" ]]; then
    echo "t1 set-up $key is cached in $prefix"
    echo "$prefix/bin/t1-trial"
    exit 0
fi
rm -rf "$prefix"
mkdir -p "$prefix/bin" "$prefix/policy"
trap 'echo "$0: the T1 set-up failed; its half-made prefix $prefix is replaced by the next call" >&2' ERR
python3 -m venv "$prefix/venv"
"$prefix/venv/bin/pip" install --quiet --disable-pip-version-check "${pins[@]}"
site="$("$prefix/venv/bin/python" -c 'import sysconfig; print(sysconfig.get_paths()["purelib"])')"
for p in "$here"/patches/*.patch; do
    patch -d "$site" -p1 --forward --quiet <"$p"
done
tar -xzf "$client" -C "$prefix/policy" --strip-components=3 --wildcards \
    '*/example/nn_client/locomotion_nn.pth' '*/example/nn_client/locomotion_nn_meta.json'
# The policy's licence (MIT) goes with it.
tar -xzf "$client" -C "$prefix/policy" --strip-components=1 --wildcards '*/LICENSE'
cp "$here/policy.py" "$here/server.py" "$prefix/bin/"
{
    echo "#!$prefix/venv/bin/python"
    tail -n +2 "$here/t1-trial"
} >"$prefix/bin/t1-trial.new"
chmod +x "$prefix/bin/t1-trial.new"
mv "$prefix/bin/t1-trial.new" "$prefix/bin/t1-trial"
echo "$key" >"$prefix/.built"
echo "t1 set-up $key is in $prefix"
echo "$prefix/bin/t1-trial"
