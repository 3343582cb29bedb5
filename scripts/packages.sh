# The system packages handblocks needs: the one place that knows them. Sourced by ./run (what a
# session needs) and tests/run (that, and what the tests need besides).
#
# To add one, add a line to the right function:
#   need "what it is for" 'a command that succeeds when it is present' package [package ...]

# What a live session needs.
hb_run_packages() {
    # Mesa's software Vulkan driver (llvmpipe), so the renderer draws on machines without a GPU.
    need "a Vulkan driver (Mesa's software one) for the renderer" \
        'ls /usr/share/vulkan/icd.d/lvp_icd.*.json' mesa-vulkan-drivers libvulkan1
}

# What the tests need besides.
hb_test_packages() {
    hb_run_packages
    # Python's venv, for the standard MCAP reader tests/run installs into target/.
    need "Python's venv (the standard MCAP reader)" \
        'python3 -c "import ensurepip, venv"' python3 python3-venv
    # Node.js and npm, for the stock Foxglove client tests/run installs into target/.
    need "Node.js and npm (the stock Foxglove client)" \
        'command -v node && command -v npm' nodejs npm
    # Chromium, for the emulated headset (a WebXR page in a real browser, headless).
    need "Chromium (the emulated headset's browser)" \
        'test -x /usr/bin/chromium' chromium
    # A TrueType font for the benchmark figures' labels (plotters draws text through ab_glyph
    # with a system font; without one the figures have no labels).
    need "a TrueType font (the benchmark figures' labels)" \
        'test -e /usr/share/fonts/truetype/dejavu/DejaVuSans.ttf' fonts-dejavu-core
}

# --- the machinery ---------------------------------------------------------------------------
HB_MISSING=()
HB_MISSING_WHY=()
need() {
    local why=$1 check=$2
    shift 2
    if ! bash -c "$check" >/dev/null 2>&1; then
        HB_MISSING+=("$@")
        HB_MISSING_WHY+=("$why")
    fi
}

# hb_install_missing WHO FUNCTION: runs FUNCTION's checks and installs what is missing with
# apt-get (as root, or through sudo). Returns 1 when something is missing and cannot be
# installed here (then it says what to install).
hb_install_missing() {
    local who=$1 list=$2
    HB_MISSING=()
    HB_MISSING_WHY=()
    "$list"
    [ ${#HB_MISSING[@]} -eq 0 ] && return 0
    local sudo=""
    if [ "$(id -u)" != 0 ]; then
        if command -v sudo >/dev/null 2>&1; then sudo="sudo"; else sudo="none"; fi
    fi
    if ! command -v apt-get >/dev/null 2>&1 || [ "$sudo" = none ]; then
        echo "$who: missing: ${HB_MISSING_WHY[*]}; install the packages ${HB_MISSING[*]}" \
             "(or your system's equivalent) and run it again" >&2
        return 1
    fi
    echo "$who: installing ${HB_MISSING[*]} (${HB_MISSING_WHY[*]})" >&2
    $sudo apt-get update -qq &&
        DEBIAN_FRONTEND=noninteractive $sudo apt-get install -y -qq "${HB_MISSING[@]}" >&2
}
