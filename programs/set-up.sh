# Sourced by the programs' set-up scripts (programs/*/): reads their
# arguments, SOURCE [CACHE], into $source_dir (absolute) and $cache (CACHE,
# else the variable named by $1, else ~/.cache/naofarm/$2). A script that
# can fetch its sources sets fetchable=1 first: SOURCE may then be left out
# ($source_dir empty). Usage errors exit 2.
set_up_arguments() {
    local cache_var="$1" name="$2"
    shift 2
    if [[ $# -gt 2 || ($# -lt 1 && -z "${fetchable:-}") ]]; then
        if [[ -n "${fetchable:-}" ]]; then
            echo "usage: $0 [SOURCE [CACHE]]" >&2
        else
            echo "usage: $0 SOURCE [CACHE]" >&2
        fi
        exit 2
    fi
    source_dir=""
    if [[ $# -ge 1 ]]; then
        if [[ ! -d "$1" ]]; then
            echo "$0: SOURCE $1 is not a directory" >&2
            exit 2
        fi
        source_dir="$(cd "$1" && pwd)"
    fi
    cache="${2:-${!cache_var:-${XDG_CACHE_HOME:-$HOME/.cache}/naofarm/$name}}"
}
