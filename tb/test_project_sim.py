"""``rosgate sim`` of the example projects, and what it does with bad input.

The Sobel/DIP application (camera -> DIP (HW) -> Sobel service (HW) -> viewer) on
photographs and random images of sizes nobody tuned to (odd widths and heights, the smallest
and a crop of a photograph), each ``<stem>_filtered.png`` compared here with OpenCV's Sobel
edge image; the paper's per-byte-lane mode against the spec's model; images the hardware
cannot take refused before anything is built; an exception in a project's ``sim.py`` reported
with its file and line; a run that stops making progress ended with what waits; and the sort
service demo with two slots on their own clock (both simulators).
"""

import json
import random
import shutil

import cv2
import numpy as np
import pytest

from host.cli import main as rosgate
from host.project_sim import run_project_sim
from tb.models import inverse_kinematics as ik_model
from tb.models.services import fibonacci
from tb.models.ball_control import BallControlModel, leg_words, servo_pulse

from .harness import ROOT, amount
from .models.image import IMAGES
from .models.sobel import sobel_byte_lanes

SOBEL_DIP = ROOT / "examples" / "sobel_dip" / "build.cfg"
PHOTO = IMAGES / "coffee_80x60.png"


def opencv_edges(pixels):
    """OpenCV's Sobel edge image: |dx| and |dy| saturated to 8 bits and added, per channel,
    BORDER_REFLECT_101 (OpenCV's default)."""
    gx = cv2.Sobel(pixels, cv2.CV_16S, 1, 0, ksize=3)
    gy = cv2.Sobel(pixels, cv2.CV_16S, 0, 1, ksize=3)
    return cv2.add(cv2.convertScaleAbs(gx), cv2.convertScaleAbs(gy))


def write_images(folder, rng):
    """Random images of odd sizes, the smallest the hardware takes, and a crop of a
    photograph with an odd width; returns their paths."""
    photo = cv2.imread(str(IMAGES / "chelsea_96x72.png"))
    w, h = rng.randrange(5, 60, 2), rng.randrange(3, 40)
    y, x = rng.randrange(0, 72 - 31), rng.randrange(0, 96 - 45)
    images = {"odd33x17": rng_image(rng, 33, 17), "min3x3": rng_image(rng, 3, 3),
              f"rand{w}x{h}": rng_image(rng, w, h), "crop45x31": photo[y:y + 31, x:x + 45]}
    paths = []
    for name, pixels in images.items():
        paths.append(folder / f"{name}.png")
        cv2.imwrite(str(paths[-1]), pixels)
    return paths


def rng_image(rng, width, height):
    return np.frombuffer(rng.randbytes(width * height * 3), np.uint8).reshape(height, width, 3)


def test_sobel_dip_runs_more_images_than_its_memory_holds_without_freeing(tmp_path):
    """40 photographs of 96x72 through a system with 1 MiB of physical memory: each takes
    about 83 KB of message buffers (the image, the service request and response), 3.3 MB in
    all, so the run completes only because a message stored again frees what the struct held;
    every image equals OpenCV's and the heap ends as small as after the first."""
    out = tmp_path / "out"
    images = ",".join(["chelsea_96x72.png"] * 40)
    assert rosgate(["sim", str(SOBEL_DIP), "--arg", f"images={images}", "--memory-mb", "1",
                    "--limit-ms", "50", "-o", str(out)]) == 0
    got = json.loads((out / "sim_results.json").read_text())
    assert len(got["images"]) == 40 and all(r["bit_exact"] for r in got["images"])
    memory = got["memory"]
    assert memory["size"] == 1 << 20 and memory["physical"] < memory["size"]
    assert memory["peak"] < 4 * 96 * 72 * 3 * 2


@pytest.mark.parametrize("value", ["0", "-5", "abc", "4096"])
def test_memory_size_option_refuses_bad_values(value, capsys):
    """``--memory-mb`` takes a whole number of MiB from 1 to 4095; anything else exits 2
    naming the value, before anything is built."""
    with pytest.raises(SystemExit) as info:
        rosgate(["sim", str(SOBEL_DIP), "--memory-mb", value])
    assert info.value.code == 2
    assert f"--memory-mb: {value!r}" in capsys.readouterr().err


def test_exhausted_memory_names_the_option(tmp_path, capsys):
    """A photograph bigger than the memory given: the run ends with exit 2 and a message
    that says how much memory there was, what used it and which option gives more."""
    out = tmp_path / "out"
    assert rosgate(["sim", str(SOBEL_DIP), "--arg", "images=coffee_640x480.png",
                    "--memory-mb", "1", "--limit-ms", "50", "-o", str(out)]) == 2
    err = capsys.readouterr().err
    assert "physical memory is exhausted: 1048576 bytes" in err and "--memory-mb" in err


@pytest.mark.parametrize("sim", ["icarus", pytest.param("verilator", marks=pytest.mark.full)])
def test_sobel_dip_equals_opencv(sim, tmp_path):
    """Every image through ``rosgate sim`` comes back equal to OpenCV's Sobel edge image
    (compared here, from the PNGs the viewer wrote), with a montage next to it; consecutive
    images leave no state behind (their byte counts differ modulo the word)."""
    rng = random.Random()
    paths = write_images(tmp_path, rng)
    out = tmp_path / "out"
    images = ",".join(["coffee_80x60.png", *map(str, paths)])
    assert rosgate(["sim", str(SOBEL_DIP), "--sim", sim, "--arg", f"images={images}",
                    "--limit-ms", "50", "-o", str(out)]) == 0
    got = json.loads((out / "sim_results.json").read_text())
    assert got["mode"] == "opencv"
    assert [r["image"] for r in got["images"]] == \
        ["coffee_80x60.png", *(p.name for p in paths)]
    for r, path in zip(got["images"], [IMAGES / "coffee_80x60.png", *paths]):
        pixels = cv2.imread(str(path))
        filtered = cv2.imread(r["filtered_png"])
        assert filtered.shape == pixels.shape, r
        assert np.array_equal(filtered, opencv_edges(pixels)), f"{path.name} differs"
        assert r["bit_exact"] and r["header_ok"], r
        montage = cv2.imread(r["montage_png"])
        assert montage.shape[1] > 3 * pixels.shape[1], r
        # at most one pixel per cycle, and the image is copied in and out over MEMIF
        assert r["cycles"] > r["width"] * r["height"], r


@pytest.mark.full      # make test: the paper's filter in the Sobel server, tb/test_reconos_apps.py
def test_sobel_dip_paper_mode(tmp_path):
    """``--param Sobel.mode=reconros``: the paper's per-byte-lane filter, checked against the
    spec's model (ReconROS' written region and rosgate's native border)."""
    out = tmp_path / "out"
    noise = rng_image(random.Random(), 32, 20)
    cv2.imwrite(str(tmp_path / "noise.png"), noise)
    assert rosgate(["sim", str(SOBEL_DIP), "--sim", "verilator", "--param",
                    "Sobel.mode=reconros", "--arg",
                    f"images=coffee_80x60.png,{tmp_path / 'noise.png'}", "--limit-ms", "50",
                    "-o", str(out)]) == 0
    got = json.loads((out / "sim_results.json").read_text())
    assert got["mode"] == "reconros"
    for r, path in zip(got["images"], [IMAGES / "coffee_80x60.png", tmp_path / "noise.png"]):
        pixels = cv2.imread(str(path))
        height, width = pixels.shape[:2]
        want, _ = sobel_byte_lanes(pixels.tobytes(), height, width * 3 // 4)
        assert cv2.imread(r["filtered_png"]).tobytes() == want, path.name
        assert (out / f"{path.stem}_reference.png").is_file()


@pytest.mark.parametrize("make,words", [
    (lambda p: cv2.imwrite(str(p), np.zeros((500, 700, 3), np.uint8)),
     ["700x500", "3..640 x 3..480"]),
    (lambda p: cv2.imwrite(str(p), np.zeros((2, 9, 3), np.uint8)), ["9x2", "3..640 x 3..480"]),
    (lambda p: p.write_text("not an image"), ["not an image OpenCV can read"]),
    (lambda p: None, ["no file"]),
], ids=["too_large", "too_small", "not_an_image", "missing"])
def test_sobel_dip_refuses_bad_images_before_building(tmp_path, capsys, make, words):
    """An image the Sobel thread cannot take, a file that is not an image and a missing file
    are refused at once (exit 2), naming the file and what is accepted; no simulator is
    built (the system's Verilog is written first, in seconds)."""
    bad = tmp_path / "bad.png"
    make(bad)
    cache = tmp_path / "cache"
    with pytest.MonkeyPatch.context() as mp:
        mp.setenv("ROSGATE_CACHE", str(cache))
        assert rosgate(["sim", str(SOBEL_DIP), "--arg", f"images=coffee_80x60.png,{bad}",
                        "-o", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err
    assert "rosgate sim: error:" in err and "sim.py:" in err and str(bad) in err, err
    for word in words:
        assert word in err, err
    assert not list(cache.glob("sim/*/obj")), "a simulator was built for a refused run"


def broken_project(tmp_path, node_source):
    """A copy of the Sobel/DIP project whose sim.py runs ``node_source`` as its only node."""
    project = tmp_path / "project"
    shutil.copytree(SOBEL_DIP.parent, project)
    text = (project / "sim.py").read_text()
    text = text.replace("NODES = [camera, viewer]", node_source + "\n\nNODES = [broken]")
    (project / "sim.py").write_text(text)
    line = text.splitlines().index(next(ln for ln in node_source.splitlines()
                                        if "# <-" in ln)) + 1
    return project / "build.cfg", line


def test_error_in_sim_py_names_file_and_line(tmp_path, capsys):
    """An exception in a node of sim.py reaches the user as its own message, with the file
    and line it came from."""
    cfg, line = broken_project(tmp_path, '''async def broken(ctx):
    await ctx.cycles(100)
    raise ZeroDivisionError("the node divided by zero")  # <-''')
    assert rosgate(["sim", str(cfg), "--sim", "icarus", "--arg", f"images={PHOTO}",
                    "-o", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err
    assert f"sim.py:{line}: ZeroDivisionError: the node divided by zero" in err, err


def test_stalled_run_ends_with_what_waits(tmp_path, capsys):
    """A node waiting for a message that never comes ends the run after ``--stall-ms`` of
    simulated inactivity, naming the waiting node and the slot in its OS call."""
    cfg, _ = broken_project(tmp_path, '''async def broken(ctx):
    await ctx.filtered.get()  # <- nothing is ever published''')
    assert rosgate(["sim", str(cfg), "--sim", "icarus", "--stall-ms", "0.5", "--arg",
                    f"images={PHOTO}", "-o", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err
    assert "no progress for 60000 cycles (0.6 ms simulated at 100 MHz)" in err, err
    assert "slot 1 in ROS_TAKE" in err and "nodes still running: broken" in err, err


def test_failed_task_of_a_node_names_its_exception(tmp_path, capsys):
    """A task a node started (not the node itself) fails: the terminal shows its exception
    with file and line, not only the log's path."""
    cfg, line = broken_project(tmp_path, '''async def _helper(ctx):
    await ctx.cycles(10)
    raise RuntimeError("the helper task broke")  # <-


async def broken(ctx):
    cocotb.start_soon(_helper(ctx))
    await ctx.cycles(1000)''')
    text = cfg.parent.joinpath("sim.py").read_text()
    cfg.parent.joinpath("sim.py").write_text("import cocotb\n" + text)
    assert rosgate(["sim", str(cfg), "--sim", "icarus", "--arg", f"images={PHOTO}",
                    "-o", str(tmp_path / "out")]) == 1
    err = capsys.readouterr().err
    assert f"sim.py:{line + 1}: RuntimeError: the helper task broke" in err, err


def test_stall_names_the_recorded_protocol_error(tmp_path, capsys):
    """A thread that publishes on its rosnode handle: the stall message carries the protocol
    error the ReconOS model recorded."""
    project = tmp_path / "project"
    shutil.copytree(ROOT / "examples" / "inverse_kinematics", project)
    thread = project / "src" / "rt_inverse" / "amaranth" / "thread.py"
    thread.write_text(thread.read_text().replace('h_pub=ctx.handle("pub")',
                                                 'h_pub=ctx.handle("node")'))
    assert rosgate(["sim", str(project / "build.cfg"), "--sim", "icarus", "--stall-ms", "0.5",
                    "--arg", "requests=2", "-o", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err
    assert "no progress" in err and "ReconOS protocol errors before: slot 0: handle 0 is " \
        "rosnode, expected rospub" in err, err


#: in test-full (make test: the sort service node runs in tb/test_reconos_apps.py, clock-crossing
#: slots in the reconos system benches)
SORT_SIMS = [pytest.param(s, marks=pytest.mark.full) for s in ("icarus", "verilator")]


@pytest.mark.parametrize("sim", SORT_SIMS)
def test_sort_service_two_slots(sim, tmp_path):
    """Both slots of ``SortDemo(*)`` (120 MHz, clock-crossing FIFOs) serve "srv"; six
    concurrent calls of 300 values each come back sorted."""
    results = run_project_sim(ROOT / "examples/sort_service/build.cfg", sim,
                              out=tmp_path / "out", args={"requests": "3", "size": "300"},
                              limit_ms=20)
    assert results["slots_running"] == [0, 1]
    assert len(results["calls"]) == 6 and results["all_sorted"], results


def test_sort_service_slots_serve_in_parallel(tmp_path):
    """Two clients call at once: each slot takes one call, so both answers come after about
    one call's time (served one after another, the second would take twice the first)."""
    results = run_project_sim(ROOT / "examples/sort_service/build.cfg", "icarus",
                              out=tmp_path / "out", args={"requests": "1", "size": "300"},
                              limit_ms=20)
    cycles = sorted(c["cycles"] for c in results["calls"])
    assert len(cycles) == 2 and results["all_sorted"], results
    assert cycles[1] < 1.5 * cycles[0], cycles


def test_image_echo_runs_its_own_camera(tmp_path):
    """examples/image_echo without --ros2: its sim.py's camera sends photographs and random
    images; each comes back unchanged, none more than sent."""
    results = run_project_sim(ROOT / "examples/image_echo/build.cfg", "icarus",
                              out=tmp_path / "out", args={"images": "5", "seed": "3"},
                              limit_ms=20)
    assert len(results["images"]) == 5 and results["all_equal"], results
    assert results["extra_echoes"] == 0 and all(i["cycles"] > 0 for i in results["images"])


@pytest.mark.parametrize("sim", ["icarus", pytest.param("verilator", marks=pytest.mark.full)])
def test_image_invert_thread_inverts_every_tail(sim, tmp_path):
    """examples/image_invert (docs/howto.md's FSM thread): random images of 0..7 pixels a
    side, so every length of the last 8-byte word and empty images occur; each comes back
    inverted, the other fields unchanged (checked by its sim.py against 255 - byte)."""
    seed = random.Random().randrange(1 << 30)
    results = run_project_sim(ROOT / "examples/image_invert/build.cfg", sim,
                              out=tmp_path / "out", args={"images": "40", "max_side": "7",
                                                          "seed": str(seed)}, limit_ms=20)
    assert results["all_equal"] and len(results["images"]) == 40, (seed, results)
    tails = {i["bytes"] % 8 for i in results["images"]}
    assert len(tails) >= 5 and any(i["bytes"] == 0 for i in results["images"]), (seed, tails)


def test_project_without_hardware_or_nodes_is_refused(tmp_path, capsys):
    """examples/sobel_topic has only an HLS thread: nothing to simulate, said so (exit 2),
    instead of 0 cycles and exit 0."""
    assert rosgate(["sim", str(ROOT / "examples/sobel_topic/build.cfg"), "--sim", "icarus",
                    "-o", str(tmp_path / "out")]) == 2
    assert "Sobel has no Amaranth thread" in capsys.readouterr().err
    project = tmp_path / "no_nodes"
    shutil.copytree(ROOT / "examples/inverse_kinematics", project)
    (project / "sim.py").unlink()
    assert rosgate(["sim", str(project / "build.cfg"), "--sim", "icarus",
                    "-o", str(tmp_path / "out")]) == 2
    assert "InverseKinematics has no sim.py" in capsys.readouterr().err


def test_status_reports_cycles_work_and_memory(tmp_path):
    """While a run goes on, the status (rosgate sim's progress line) says how many cycles
    ran, how many of the nodes' images are done and how much memory is in use."""
    seen = []
    results = run_project_sim(SOBEL_DIP, "icarus", out=tmp_path / "out",
                              args={"images": ",".join([str(PHOTO)] * 4)}, status=seen.append,
                              status_seconds=0.0, log=lambda cycle, text: None)
    assert len(results["images"]) == 4 and len(seen) >= 2, seen
    cycles = [s["cycle"] for s in seen]
    assert cycles == sorted(cycles) and cycles[-1] <= results["cycles"]
    assert {s["unit"] for s in seen} == {"images"} and {s["total"] for s in seen} == {4}
    assert [s["done"] for s in seen] == sorted(s["done"] for s in seen)
    assert all(0 < s["memory_in_use"] <= results["memory"]["peak"] for s in seen), seen
    assert all(s["memory_size"] == 256 << 20 for s in seen)
    from host.cli import _SimStatus
    line = _SimStatus.describe({**seen[-1], "done": 1, "total": 4, "seconds": 30.0})
    assert "1 of 4 images, about 1 min 30 s left" in line and "MiB in use" in line, line


def test_sort_action_example(tmp_path):
    """examples/sort_action on Icarus: goals of the block size are accepted, sorted, with
    feedback rising to 100 %; a larger goal is rejected."""
    results = run_project_sim(ROOT / "examples/sort_action/build.cfg", "icarus",
                              out=tmp_path / "a", args={"goals": "2", "size": "256"},
                              limit_ms=5)
    assert [g["accepted"] for g in results["goals"]] == [True, True]
    assert all(g["sorted"] and g["feedback"][-1] == 100.0 for g in results["goals"]), results
    results = run_project_sim(ROOT / "examples/sort_action/build.cfg", "icarus",
                              out=tmp_path / "b", args={"goals": "1", "size": "257"},
                              limit_ms=5)
    assert results["goals"] == [{"goal": 0, "size": 257, "accepted": False}]


@pytest.mark.parametrize("sim", ["icarus", pytest.param("verilator", marks=pytest.mark.full)])
def test_services_over_hardware_topics(sim, tmp_path):
    """examples/hw_services: two hardware clients call the hardware sort service at once (each
    reply is its request sorted); two hardware clients send goals to the hardware Fibonacci
    server at once: valid goals end SUCCEEDED with F(0..order) after ``order`` feedbacks (a
    goal that found the server busy was refused and sent again), invalid orders are refused,
    a cancel after 3 feedbacks ends the goal CANCELED with the values sent so far, a cancel of
    a goal never sent is answered ERROR_UNKNOWN_GOAL_ID. Software calls of /sort through the
    generated service gateway (ServiceGatewayThread, one more client of the hardware service)
    come back sorted; one larger than the server's block comes back empty, and the calls
    after it are served. Software goals of /fibonacci through the generated action gateway
    (ActionGatewayThread): order 12 SUCCEEDED with its 12 feedbacks, order 47 rejected by the
    hardware server, order 46 canceled after its first feedback ends CANCELED with the values
    sent before."""
    results = run_project_sim(ROOT / "examples/hw_services/build.cfg", sim, out=tmp_path / "o",
                              args={"calls": "2", "size": "64"},
                              thread_params=["SortServer.block_size=64",
                                             "FibServer.step_cycles=40"], limit_ms=5)
    calls = results["sort_calls"]
    assert len(calls) == 4 and all(c["sorted"] for c in calls), calls
    software = results["software_calls"]
    assert [c["values"] > 64 for c in software] == [False, True, False, False], software
    assert all(c["sorted"] for c in software), software
    goals = results["software_goals"]
    assert [(g["order"], g["accepted"], g.get("status")) for g in goals] == \
        [(12, True, 4), (47, False, None), (46, True, 5)], goals
    assert goals[0]["values"] == fibonacci(12) and goals[0]["feedbacks"] == 12
    canceled = goals[2]["values"]
    assert 2 <= len(canceled) < 47 and canceled == fibonacci(len(canceled) - 1), canceled
    goals = {(g["client"], g["order"], g["status"]): g for g in results["fibonacci_goals"]}
    for client, order in (("FibClientA", 10), ("FibClientB", 20), ("FibClientB", 0)):
        g = goals[(client, order, 0)]
        assert (g["result"], g["feedbacks"], g["values"]) == (4, order, fibonacci(order)), g
    for client, order in (("FibClientA", 47), ("FibClientB", -1)):
        assert goals[(client, order, 1)]["values"] == []
    cancelled = goals[("FibClientA", 30, 0)]
    assert (cancelled["result"], cancelled["cancel"]) == (5, 0), cancelled
    assert cancelled["feedbacks"] >= 3 and cancelled["values"] == fibonacci(cancelled["feedbacks"])
    stranger = goals[("FibClientA", 5, 0)]
    assert (stranger["result"], stranger["cancel"], stranger["values"]) == (4, 2, fibonacci(5))


@pytest.mark.parametrize("sim", ["icarus", pytest.param("verilator", marks=pytest.mark.full)])
def test_inverse_kinematics_node(sim, tmp_path):
    """examples/inverse_kinematics: ReconROS' test client's words through the hardware node;
    every answer equals the ap_fixed model (tb/models/inverse_kinematics.py), the words for
    leg 6 are dropped by the kernel and the node serves the next request."""
    results = run_project_sim(ROOT / "examples/inverse_kinematics/build.cfg", sim,
                              out=tmp_path / "out", args={"requests": "60"}, limit_ms=5)
    requests = results["requests"]
    assert len(requests) == 60 and results["answered"] == 52
    for r in requests:
        assert r["word"] == ik_model.client_word(r["i"])
        want = None if r["i"] % 7 == 6 else ik_model.solve(r["word"])
        assert r["answer"] == want, r


BALL = ROOT / "examples" / "ball_on_plate"


def _ball_plant():
    """examples/ball_on_plate/sim.py as a module (its plant, replayed by the replica)."""
    import importlib.util
    spec = importlib.util.spec_from_file_location("ball_on_plate_sim", BALL / "sim.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def ball_loop_replica(periods, x, y, clock_hz):
    """The loop with the golden models in place of the hardware (BallControl's fixed-point
    model, the ap_fixed inverse kinematics, the PWM widths), the same plant, and the
    hardware's timing: a touch sample's widths drive the period after the one it is taken
    in. Returns (touch words, widths per period)."""
    plant = _ball_plant()
    control = BallControlModel(period="0.02")
    ball = plant.Ball(x, y)
    touches, widths_per_period, pending = [ball.touch_word()], [], []
    tilt = (0.0, 0.0)

    def chain(word):
        def raw(v):
            return v - 4096 if v & 0x800 else v
        alpha, beta = control.update(raw(word & 0xFFF), raw(word >> 16 & 0xFFF))
        return [servo_pulse(ik_model.solve(w) >> 21, clock_hz=clock_hz)
                for w in leg_words(alpha, beta)]

    for n in range(periods):
        pending.append(chain(touches[-1]))
        widths = pending[n - 1] if n else [0] * 6
        widths_per_period.append(widths)
        if all(widths):
            tilt = plant.plate_tilt([plant.arm_angle(w, clock_hz) for w in widths], tilt)
        ball.roll(tilt[0], tilt[1], plant.PERIOD_S)
        touches.append(ball.touch_word())
    return touches, widths_per_period


def test_ball_on_plate_loop_equals_the_models(tmp_path):
    """examples/ball_on_plate on Icarus, 8 servo periods (20 in make test-full; the PWM counting
    at 250 kHz, 5,000 cycles a period): every touch sample and every period's six measured
    pulse widths equal the replica built from the golden models; the chain answers a sample
    in under a period."""
    periods, clock_hz = amount(8, 20), 250_000
    results = run_project_sim(BALL / "build.cfg", "icarus", out=tmp_path / "out",
                              args={"periods": str(periods)},
                              thread_params=[f"Servo.pwm_clock_hz={clock_hz}"], limit_ms=5)
    touches, widths = ball_loop_replica(periods, 90.0, -60.0, clock_hz)
    assert results["touches"] == touches[:periods + 1]
    assert [p["widths"] for p in results["periods"]] == widths
    assert max(results["latencies"]) < 20_000 * clock_hz // 1_000_000   # one period


@pytest.mark.full
def test_ball_on_plate_settles(tmp_path):
    """The full example (Verilator, PWM at 1 MHz, 300 periods = 6 s): the ball dropped
    108 mm off centre ends within 3 mm of it."""
    results = run_project_sim(BALL / "build.cfg", "verilator", out=tmp_path / "out",
                              args={"periods": "300"}, limit_ms=100)
    assert results["final_radius_mm"] < 3.0, results["final_radius_mm"]


@pytest.mark.full
@pytest.mark.parametrize("sim", ["verilator", "icarus"])
def test_av_chain_reconros_variant(sim, tmp_path):
    """examples/av_chain, its seven nodes ReconOS threads with their topics through memory,
    the scene at a fifth of its size: bad frames are dropped by the node they reach and
    reported with their number, the chain then runs frames that are dark, red, green: every
    stage as OpenCV computes it (the projection within 1), lane centres near the scene's
    ground truth, a stop event on each red frame and a start on the first green one, one
    command per frame."""
    results = run_project_sim(ROOT / "examples/av_chain/build.cfg", sim, out=tmp_path / "o",
                              args={"frames": "3", "red_from": "1", "green_from": "2",
                                    "bad_frames": "1"},
                              thread_params=["*.scale=0.2", "*.pixels_per_beat=1"], limit_ms=20)
    assert [(b["node"], b["frame"]) for b in results["bad_frames"]] == [
        ("Compensation", 0), ("Compensation", 1), ("Compensation", 2), ("Compensation", 3),
        ("LaneFollowing", 0)]
    frames = results["frames"]
    assert [f["light"] for f in frames] == ["dark", "red", "green"]
    assert results["stages_bit_exact"], frames
    assert (results["stops"], results["starts"]) == ([1], [2])
    assert all(abs(f["centre"] - f["truth"]) <= 5 for f in frames), frames
    assert [f["speed"] > 0 for f in frames] == [True, False, True], frames
