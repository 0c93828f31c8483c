#!/usr/bin/env bash
# skyref's one entry point on a fresh Debian 12 machine (as root):
#   bash run.sh demo   set everything up, then render the default scene (scenes/earth-clear.toml)
#                      to out/earth-clear.exr and out/earth-clear.png
#   bash run.sh test   set everything up, then run the test suite (what CI runs)
#   bash run.sh setup  only set up
# Set-up is idempotent: system packages are installed only when missing, the virtual
# environment (.venv) is rebuilt only when pyproject.toml changed.
set -euo pipefail
cd "$(dirname "$0")"

VENV=${SKYREF_VENV:-.venv}
STAMP="$VENV/.skyref-installed"

apt_install() {  # apt_install PACKAGE...: install Debian packages (needs root and apt-get)
    if ! command -v apt-get >/dev/null; then
        echo "run.sh: please install: $*" >&2; exit 1
    fi
    local sudo=""; [ "$(id -u)" = 0 ] || sudo="sudo"
    if [ -z "${APT_UPDATED:-}" ]; then $sudo apt-get update -qq; APT_UPDATED=1; fi
    DEBIAN_FRONTEND=noninteractive $sudo apt-get install -y -qq --no-install-recommends "$@"
}

setup() {
    local need=()
    command -v python3 >/dev/null || need+=(python3)
    python3 -c 'import venv, ensurepip' 2>/dev/null || need+=(python3-venv)
    command -v gcc >/dev/null || need+=(gcc)  # tests compile the exported Hosek C header
    [ ${#need[@]} -eq 0 ] || apt_install "${need[@]}"
    # Dr.Jit needs libLLVM >= 17 (Debian's default 15/16 crash it): skyref._llvm decides.
    if ! python3 -m skyref._llvm; then
        echo "run.sh: no working libLLVM found; installing libllvm19" >&2
        apt_install libllvm19
    fi
    local want; want=$(sha256sum pyproject.toml | cut -d' ' -f1)
    if [ ! -f "$STAMP" ] || [ "$(cat "$STAMP")" != "$want" ]; then
        echo "run.sh: creating $VENV and installing skyref with its test dependencies" >&2
        python3 -m venv "$VENV"
        "$VENV/bin/python" -m pip install -q --upgrade pip
        "$VENV/bin/python" -m pip install -q -e '.[test,fit,batch]'
        echo "$want" > "$STAMP"
    fi
}

case "${1:-}" in
    setup) setup ;;
    demo)
        setup
        "$VENV/bin/skyref" render scenes/earth-clear.toml -o out/earth-clear.exr --png out/earth-clear.png --annotate
        ;;
    test)
        setup
        shift
        # Two worker processes, a test file each at a time: a new kernel configuration compiles
        # on one core for minutes (docs/design.md), so two files compile side by side. The
        # slowest tests are listed at the end, to show where a run's time went.
        exec "$VENV/bin/python" -m pytest -n 2 --dist loadfile --durations=30 "$@"
        ;;
    *) echo "usage: bash run.sh demo|test|setup" >&2; exit 2 ;;
esac
