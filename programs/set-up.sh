# Sourced by the programs' set-up scripts (programs/*/): reads their
# arguments, SOURCE [CACHE], into $source_dir (absolute) and $cache (CACHE,
# else the variable named by $1, else ~/.cache/naofarm/$2). Usage errors
# exit 2.
set_up_arguments() {
    local cache_var="$1" name="$2"
    shift 2
    if [[ $# -lt 1 || $# -gt 2 ]]; then
        echo "usage: $0 SOURCE [CACHE]" >&2
        exit 2
    fi
    if [[ ! -d "$1" ]]; then
        echo "$0: SOURCE $1 is not a directory" >&2
        exit 2
    fi
    source_dir="$(cd "$1" && pwd)"
    cache="${2:-${!cache_var:-${XDG_CACHE_HOME:-$HOME/.cache}/naofarm/$name}}"
}
