# Sourced by the device_*.sh benchmark scripts: device_info FILE writes what the machine is
# (date, host, python, glslang, nvidia-smi, vulkaninfo's devices) into FILE. Needs $PYTHON.
device_info() {
    {
        echo "date: $(date -u +%FT%TZ)"
        echo "host: $(uname -a)"
        echo "python: $("$PYTHON" --version 2>&1)"
        echo "cpu: $(grep -m1 '^model name' /proc/cpuinfo | cut -d: -f2- | sed 's/^ //')" \
             "($(nproc) threads)"
        echo "glslang: $(glslangValidator --version 2>&1 | head -1)"
        if command -v nvidia-smi >/dev/null; then
            nvidia-smi --query-gpu=name,driver_version,memory.total,clocks.sm,clocks.mem,\
clocks.max.sm,clocks.max.mem,power.limit --format=csv 2>&1 || true
        fi
        if command -v vulkaninfo >/dev/null; then
            vulkaninfo --summary 2>&1 | sed -n '/Devices:/,$p' || true
        fi
    } >"$1"
}
