# Sourced by the device_*.sh scripts on the GPU machine: `. device_ready.sh "rfw, vulkan"`
# sources device_env.sh (its log in $OUT/env.log) where the carried wheels are and $PYTHON
# cannot import those modules yet; the caller's -e and -u are kept.
if [[ -d .whl ]] && ! "$PYTHON" -c "import $1" 2>/dev/null; then
    _rfw_flags=$-
    set +eu  # device_env.sh is written for a plain shell
    . "$(dirname "${BASH_SOURCE[0]}")/device_env.sh" >"$OUT/env.log" 2>&1
    [[ $_rfw_flags == *e* ]] && set -e
    [[ $_rfw_flags == *u* ]] && set -u
    unset _rfw_flags
fi
