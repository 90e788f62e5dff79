"""Where a cast's ray and hit streams live: staged (copied on the GPU) or mapped (the trace reads
and writes host-visible memory), by ``RFW_RAYCAST_MAPPED`` or the device's memory types."""

from __future__ import annotations

from ..allocation import DEVICE_LOCAL, HOST_CACHED, HOST_COHERENT, HOST_VISIBLE, flags_of
from ..device import VkDevice


def mapped_type_bits(device: VkDevice, *, readback: bool) -> int:
    """The memory types (as bits) that suit a mapped stream: host-visible and coherent and
    device-local, and for one the host reads (``readback``) also host-cached (uncached
    reads are slow); for reads without such memory, any host-cached type."""
    need = [DEVICE_LOCAL, HOST_VISIBLE, HOST_COHERENT] + [HOST_CACHED] * readback
    bits = _type_bits(device, need)
    return bits or (_type_bits(device, [HOST_VISIBLE, HOST_COHERENT, HOST_CACHED])
                    if readback else 0)


def _type_bits(device: VkDevice, names: list[str]) -> int:
    need = flags_of(names)
    return sum(1 << i for i, (props, _) in enumerate(device.memory_types)
               if props & need == need)


# RFW_RAYCAST_MAPPED: which streams the trace reads and writes in mapped memory; "host":
# both, the rays too in host-cached memory (see rays_in_host_memory)
PLACEMENTS = {"0": (False, False), "1": (True, True), "rays": (True, False),
              "hits": (False, True), "host": (True, True)}


def mapped_streams(device: VkDevice) -> tuple[bool, bool]:
    """Whether casts on ``device`` map (rays, hits) rather than stage them (see
    :class:`RayBuffers`). ``RFW_RAYCAST_MAPPED`` says so: ``0`` (neither), ``1`` (both),
    ``rays``, ``hits`` or ``host`` (both, see :func:`rays_in_host_memory`); unset (or
    ``auto``) both where memory is device-local, host-visible and host-cached at once
    (unified memory: no copy is worth making), else neither: a discrete GPU stages."""
    from rfw import env

    value = env.get("RFW_RAYCAST_MAPPED")  # PLACEMENTS or auto, checked there
    if value != "auto":
        return PLACEMENTS[value]
    unified = bool(_type_bits(device, [DEVICE_LOCAL, HOST_VISIBLE, HOST_COHERENT,
                                       HOST_CACHED]))
    return unified, unified


def rays_in_host_memory() -> bool:
    """Whether mapped rays go to host-cached memory (``RFW_RAYCAST_MAPPED=host``) rather
    than device-local host-visible memory where there is such. On a discrete GPU the host
    then writes them at the speed of its own memory, as into a staging buffer, and the
    trace reads them across the bus instead of a copy doing so first (the H200 at 921,600
    rays: the staged copy in took 0.62 ms of GPU time, writing device-local host-visible
    memory 2.64 ms of host time against 1.63 for host-cached staging)."""
    from rfw import env

    return env.get("RFW_RAYCAST_MAPPED") == "host"
