"""Probe a machine's Vulkan device through vkext: capabilities, properties, real aliasing.

    python3 scripts/device_probe.py [--json OUT]
"""

import json
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from rfw.graph import GraphBuilder, Texture, compile
from vkext.device import VkDevice
from vkext.memory import memory_options, plan_heaps


def main() -> int:
    dev = VkDevice(validation=False)
    try:
        info = {**dev.describe(), "caps": sorted(dev.caps)}
        props = dev.properties()
        info["properties"] = {k: v for k, v in props.items() if isinstance(v, int | float | str)}
        g = GraphBuilder("chain", size=(1920, 1080))
        prev = None
        for i in range(4):
            p = g.add_pass(f"p{i}", "compute")
            if prev:
                p.input("src", prev)
            p.output("out", Texture("rgba16float"))
            prev = f"p{i}.out"
        graph = g.output(prev).build()
        plan = compile(graph)
        options = memory_options(plan, dev)
        plan = compile(graph, memory=options)
        aliased = plan_heaps(plan, dev)
        separate = plan_heaps(plan, dev, no_alias=True)
        info["aliasing"] = {"plan_transient_bytes": plan.transient_bytes,
                            "allocated_aliased": aliased.allocated_bytes,
                            "allocated_unaliased": separate.allocated_bytes,
                            "image_alignment": options.image_alignment}
        aliased.destroy()
        separate.destroy()
    finally:
        dev.destroy()
    text = json.dumps(info, indent=2, default=str)
    print(text)
    if len(sys.argv) > 2 and sys.argv[1] == "--json":
        Path(sys.argv[2]).write_text(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
