"""cocotb side of ``make bench`` for the streaming kernels: each kernel alone, no idle and no
backpressure, on the 640x480 photograph (image kernels; two frames back to back) or on its
items (sort, PID, inverse kinematics); every output checked against its golden model; the
cycle counts written to ``ROSGATE_BENCH_OUT``."""

import json
import os

import cocotb
from cocotbext.axi import AxiStreamFrame

from tb.kernels_control_tb import ControlTB, int16, pid_word
from tb.kernels_image_tb import KernelsTB
from tb.models import image as golden
from tb.models import inverse_kinematics as ik_model
from tb.models.ball_control import BallControlModel, leg_words
from tb.models.pid import AvrPid


@cocotb.test()
async def measure_kernels(dut):
    params = json.loads(os.environ["ROSGATE_PARAMS"])
    records = {}
    if "cnn" in params["kernels"]:
        from tb.kernels_mnist_tb import MnistTB, check, held_out
        tb = MnistTB(dut)
        await tb.reset()
        test_x, test_y = held_out()
        results, latencies = await tb.classify(test_x[:50])
        check(results, test_x[:50])
        records["mnist"] = {"cycles": max(latencies), "items": 1}
    elif "sort" in params["kernels"]:
        tb = ControlTB(dut, seed=1)
        await tb.reset()
        tb.set_pauses(0, 0)
        rng = tb.rng
        block = [rng.randrange(1 << 32) for _ in range(2048)]
        port = tb.ports["sort"]
        start = tb.cycle
        await port.source.send(AxiStreamFrame(b"".join(v.to_bytes(4, "little") for v in block)))
        await tb.wait_words("sort", 2048, 30_000)
        assert [d for d, _, _ in port.sink.packets[0].beats] == sorted(block)
        records["sort"] = {"cycles": port.sink.packets[0].cycles[-1] - start, "items": 1}

        await tb.load_pid(256, 64, 32)
        pairs = [(rng.randrange(-3000, 3000), rng.randrange(-3000, 3000)) for _ in range(1000)]
        pid = tb.ports["pid"]
        await pid.source.send(AxiStreamFrame(b"".join(pid_word(*p).to_bytes(4, "little")
                                                      for p in pairs)))
        await tb.wait_words("pid", len(pairs), 5000)
        model = AvrPid(256, 64, 32)
        assert [int16(w) for w in pid.words()] == [model.update(*p) for p in pairs]
        c = pid.sink.packets[0].cycles
        records["pid"] = {"cycles": c[-1] - c[0] + 1, "items": len(pairs)}

        words = [w for w in (ik_model.client_word(i) for i in range(200)) if w & 7 < 6]
        ik = tb.ports["ik"]
        for w in words:
            await ik.source.send(AxiStreamFrame(w.to_bytes(4, "little")))
        await tb.wait_words("ik", len(words), 300 * len(words))
        assert ik.words() == [ik_model.solve(w) for w in words]
        ends = [c for p in ik.sink.packets for c in p.cycles]
        records["ik"] = {"cycles": ends[-1] - ends[0], "items": len(words) - 1}

        samples = [(rng.randrange(-2048, 2048), rng.randrange(-2048, 2048)) for _ in range(50)]
        ball = tb.ports["ball"]
        start = tb.cycle
        for raw in samples:
            word = (raw[0] & 0xFFF) | ((raw[1] & 0xFFF) << 16)
            await ball.source.send(AxiStreamFrame(word.to_bytes(4, "little")))
        await tb.wait_words("ball", 6 * len(samples), 400 * len(samples))
        model = BallControlModel()
        assert ball.words() == [w for raw in samples for w in leg_words(*model.update(*raw))]
        records["ball"] = {"cycles": ball.sink.packets[-1].cycles[-1] - start,
                           "items": len(samples)}
    else:
        tb = KernelsTB(dut, seed=1)
        await tb.reset()
        tb.set_pauses(0, 0)
        image = golden.load_image("coffee_640x480.png")
        for name, k in tb.kernels.items():
            start = tb.cycle
            await tb.run_frames({name: [(image, {}), (image, {})]}, timeout_cycles=2_000_000)
            ends = [p.cycles[-1] - start for p in k.sink.packets]
            h, w = k.frame_image(image).shape[:2]
            records[name] = {"first_frame": ends[0], "period": ends[1] - ends[0],
                             "width": w, "height": h}
            dut._log.info("%s: %s", name, records[name])
    with open(os.environ["ROSGATE_BENCH_OUT"], "w") as f:
        json.dump(records, f)
