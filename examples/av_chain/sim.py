"""The camera and the reference of the lane-following chain for ``rosgate sim``
(docs/av_chain.md).

The camera publishes the example's driving scene (scene.py) on /camera/image, one frame at a
time: the next frame goes out when the chain's command for the last one has arrived on /cmd
(the latency the fpgaDDS paper calls chain alpha, measured from the publication to the
command). Every frame is also run through the chain in software (host.autorace, OpenCV) and
each topic's message compared with it: the compensated and blurred images byte for byte, the
bird's-eye view within 1 per byte (OpenCV computes it in float32), the lane result, the
events on /light/stop and /light/start, the command.

``--arg frames=N`` (default 100), ``--arg seed=S`` (1), ``--arg red_from=K``,
``--arg green_from=K`` (30 % and 60 % of the frames), ``--arg bad_frames=1``: before the
scene, frames each node must drop (a wrong size, a wrong encoding, a step that does not fit
the width, a short payload to the compensation; a wrong size straight to lane following).
"""

import math
import sys
from pathlib import Path

import numpy as np

from gen.av_chain import scaled_config
from hdl.kernels.lane import DRIVE_COMMAND, LANE_RESULT
from host.autorace import SoftwareChain
from host.reconos.messages import image_message as image_msg
from host.sim_args import SimArg

sys.path.insert(0, str(Path(__file__).resolve().parent))
import scene  # noqa: E402  (the example's scene generator, next to this file)

TOPICS = {"compensated": "/image/compensated", "blurred": "/image/blurred",
          "projected": "/image/projected", "lane": "/lane", "stop": "/light/stop",
          "start": "/light/start", "command": "/cmd"}


def chain_settings(project):
    """``(scale, pixels_per_beat)`` of the project's threads (they must agree)."""
    seen = {(float(t.params.get("scale", 1)), int(t.params.get("pixels_per_beat", 4)))
            for t in project.threads}
    if len(seen) != 1:
        raise ValueError(f"the threads' scale and pixels_per_beat differ: {sorted(seen)}; set "
                         "them for all with --param '*.scale=...'")
    return seen.pop()


def bad_frames(config):
    """``(topic, message, node)``: frames the node must drop."""
    (cw, ch), (bw, bh) = config.camera, config.bev
    grey = np.full((ch, cw, 3), 128, np.uint8)
    return [
        ("/camera/image", image_msg(np.full((ch, cw - 8, 3), 128, np.uint8), 0),
         "Compensation"),
        ("/camera/image", image_msg(grey, 0, encoding="rgb8"), "Compensation"),
        ("/camera/image", image_msg(grey, 0, step=3 * cw + 24,
                                    data=bytes((3 * cw + 24) * ch)), "Compensation"),
        ("/camera/image", image_msg(grey, 0, data=grey.tobytes()[:-24]), "Compensation"),
        ("/image/projected", image_msg(np.full((bh - 1, bw, 3), 128, np.uint8), 0),
         "LaneFollowing"),
    ]


def setup(ctx):
    scale, ppc = chain_settings(ctx.project)
    ctx.config = scaled_config(scale, ppc)
    ctx.subs = {k: ctx.broker.subscribe(t) for k, t in TOPICS.items()}
    ctx.commands = []
    if ctx.playback is not None:
        # a frame's events and command are compared with the software chain's for that frame
        # alone: the next frame goes once the command for the last has come
        ctx.playback.hold()
    ctx.results.update(variant="reconros", scale=scale, ppc=ppc, clock_mhz=ctx.clock_mhz,
                       frames=[], bad_frames=[])


def _compare(ctx, k, image_bgr, stamp, sub, command):
    """Frame ``k``'s messages on every topic (their ``header.stamp`` that of the camera frame,
    ``stamp``) against the software chain run on ``image_bgr``; returns the frame's report
    and the reference's step."""
    (cw, ch), (bw, bh) = ctx.config.camera, ctx.config.bev

    def image(name, w, h):
        msg = sub[name].get_nowait()
        if msg is None:
            raise AssertionError(f"frame {k}: nothing on {TOPICS[name]}")
        geometry = (msg["width"], msg["height"], msg["encoding"], msg["step"])
        if geometry != (w, h, "bgr8", 3 * w) or len(msg["data"]) != 3 * w * h:
            raise AssertionError(f"frame {k}: {TOPICS[name]} is {geometry} with "
                                 f"{len(msg['data'])} bytes; expected {w}x{h} bgr8")
        if msg["header"]["stamp"] != stamp:
            raise AssertionError(f"frame {k}: {TOPICS[name]} has the stamp "
                                 f"{msg['header']['stamp']}, the camera frame {stamp}")
        return np.frombuffer(msg["data"], np.uint8).reshape(h, w, 3)
    a, b = image("compensated", cw, ch), image("blurred", cw, ch)
    c = image("projected", bw, bh)
    # lane following and control follow the hardware's bird's-eye view (within 1 of OpenCV)
    step = ctx.reference.step(image_bgr, bev=c)
    diff = np.abs(c.astype(int) - step.projected.astype(int))
    lane = LANE_RESULT.from_bits(sub["lane"].get_nowait()["data"])
    got_lane = (lane.centre if lane.has_centre else None, lane.left if lane.has_left else None,
                lane.right if lane.has_right else None)
    cmd = DRIVE_COMMAND.from_bits(command["data"])
    return {"compensation_exact": bool((a == step.compensated).all()),
            "blur_exact": bool((b == step.blurred).all()),
            "projection_max_diff": int(diff.max()),
            "projection_off_by_one": int((diff.max(axis=2) > 0).sum()),
            "lane_equal": got_lane == tuple(step.lane),
            "centre": got_lane[0], "speed": int(cmd.speed), "turn": int(cmd.turn),
            "command_equal": (int(cmd.speed), int(cmd.turn)) == tuple(step.command)}, step


async def camera(ctx):
    args = ctx.args
    if args.get("bad_frames", "0") == "1":
        for topic, msg, node in bad_frames(ctx.config):
            ctx.broker.publish(topic, msg)
            number = await ctx.resource(node, "bad_frames").state.get()
            ctx.results["bad_frames"].append({"node": node, "frame": number,
                                              "encoding": msg["encoding"],
                                              "size": [msg["width"], msg["height"]]})
            ctx.log(f"camera: {node} dropped its frame {number} ({msg['width']}x"
                    f"{msg['height']} {msg['encoding']}, {len(msg['data'])} bytes)")
        for sub in ctx.subs.values():       # the bad frame sent to /image/projected
            while sub.get_nowait() is not None:
                pass
    ctx.reference = SoftwareChain(ctx.config)
    events = ([], [], [], [])
    if args.get("images"):
        paths = args["images"].split(",")
        for k, path in enumerate(paths):
            msg = image_msg(_read_frame(ctx.config, path), k)
            start = ctx.now()
            ctx.broker.publish("/camera/image", msg)
            await _command(ctx)
            _check_frame(ctx, k, msg, start, None, None, events, len(paths))
    else:
        count = int(args.get("frames", 100))
        geometry = scene.Geometry(ctx.config.camera[0] / scene.CAMERA_SIZE[0])
        red_from = int(args["red_from"]) if "red_from" in args else None
        green_from = int(args["green_from"]) if "green_from" in args else None
        for frame in scene.frames(count, seed=int(args.get("seed", 1)), red_from=red_from,
                                  green_from=green_from, geometry=geometry):
            msg = image_msg(frame.image, frame.index)
            start = ctx.now()
            ctx.broker.publish("/camera/image", msg)
            await _command(ctx)
            _check_frame(ctx, frame.index, msg, start, frame.centre, frame.light, events,
                         count)
    _finish(ctx, events)


async def played_camera(ctx):
    """With ``--play``: every camera frame the bag gave the chain (a recording's
    ``/camera/image``, or a topic remapped onto it) compared like the scene's, without
    ground truth."""
    ctx.reference = SoftwareChain(ctx.config)
    events = ([], [], [], [])
    k = 0
    while (played := await ctx.playback.next("/camera/image")) is not None:
        await _command(ctx)
        _check_frame(ctx, k, played.value, played.cycle, None, None, events,
                     ctx.playback.plan.total)
        ctx.playback.release()
        k += 1
    if k == 0:
        raise ValueError("--play: the bag gave the chain no camera frame it could take")
    _finish(ctx, events)


async def _command(ctx):
    """Wait for the chain's next command; keep it with the cycle it came."""
    command = await ctx.subs["command"].get()
    ctx.commands.append((ctx.now(), command))


def _check_frame(ctx, k, msg, start, truth, light, events, total):
    """Compare frame ``k`` (the camera message ``msg``, published at cycle ``start``) on
    every topic, with the chain's next command; ``truth`` and ``light`` from the scene
    (``None`` for frames from files or a bag)."""
    arrived, command = ctx.commands.pop(0)
    cycles = arrived - start
    image = np.frombuffer(msg["data"], np.uint8).reshape(msg["height"], msg["width"], 3)
    report, step = _compare(ctx, k, image, msg["header"]["stamp"], ctx.subs, command)
    entry = {"frame": k, "cycles": cycles, "truth": truth, "light": light, **report}
    stops, starts, expected_stops, expected_starts = events
    for name, got, want, fired in (("stop", stops, expected_stops, step.stop),
                                   ("start", starts, expected_starts, step.start)):
        while (event := ctx.subs[name].get_nowait()) is not None:
            got.append(event["data"])
        if fired:
            want.append(k)
    ctx.results["frames"].append(entry)
    ctx.progress(len(ctx.results["frames"]), total, "frames")
    ctx.log(f"camera: frame {k}: {cycles} cycles, centre {entry['centre']}"
            + (f" (truth {truth:.1f})" if truth is not None else "")
            + f", speed {entry['speed']} turn {entry['turn']}")


def _read_frame(config, path):
    """A camera frame from an image file: bgr8 at the chain's camera size, else an error
    naming the file."""
    import cv2
    pixels = cv2.imdecode(np.fromfile(path, np.uint8), cv2.IMREAD_COLOR)
    if pixels is None:
        raise ValueError(f"--arg images: {path} is not an image OpenCV can read")
    reason = _frame_problem(config, image_msg(pixels, 0))
    if reason:
        raise ValueError(f"--arg images: {path}: {reason}")
    return pixels


def _frame_problem(config, msg):
    """Why the chain cannot take camera message ``msg``, or ``None``."""
    cw, ch = config.camera
    if msg["encoding"] != "bgr8":
        return f"encoding {msg['encoding']!r}; the chain takes bgr8"
    if (msg["width"], msg["height"]) != (cw, ch):
        return (f"{msg['width']}x{msg['height']}; the chain's camera is {cw}x{ch} (set the "
                f"threads' scale with --param '*.scale=...')")
    if msg["step"] != 3 * cw or len(msg["data"]) != 3 * cw * ch:
        return (f"step {msg['step']} and {len(msg['data'])} data bytes; bgr8 at {cw}x{ch} "
                f"needs step {3 * cw} and {3 * cw * ch} bytes")
    return None


def accepts(ctx, name, value):
    """A camera frame from DDS or a bag that the chain cannot take (its nodes would drop it
    and count it): the reason, or ``None``."""
    if name != "/camera/image":
        return None
    return _frame_problem(ctx.config, value)


def check(ctx):
    """Refuse, before anything is built, an image file the chain cannot take."""
    if ctx.args.get("images"):
        config = scaled_config(*chain_settings(ctx.project))
        for path in ctx.args["images"].split(","):
            _read_frame(config, path)


def _finish(ctx, events):
    stops, starts, expected_stops, expected_starts = events
    frames = ctx.results["frames"]
    cycles = [f["cycles"] for f in frames]
    mean = sum(cycles) / len(cycles)
    errors = [abs(f["centre"] - f["truth"]) for f in frames
              if f["centre"] is not None and f["truth"] is not None]
    exact = all(f["compensation_exact"] and f["blur_exact"] and f["projection_max_diff"] <= 1
                and f["lane_equal"] and f["command_equal"] for f in frames)
    ctx.results.update(
        ground_truth=all(f["truth"] is not None for f in frames),
        stops=stops, starts=starts, expected_stops=expected_stops,
        expected_starts=expected_starts, events_equal=(stops, starts) == (expected_stops,
                                                                         expected_starts),
        mean_cycles=mean, sd_cycles=math.sqrt(sum((c - mean) ** 2 for c in cycles)
                                              / len(cycles)),
        lane_centre_max_error_px=max(errors) if errors else None, stages_bit_exact=exact)
    ms = mean / (ctx.clock_mhz * 1000)
    ctx.log(f"camera: {len(frames)} frames, chain alpha {mean:,.0f} cycles = {ms:.3f} ms at "
            f"{ctx.clock_mhz:g} MHz (sd {ctx.results['sd_cycles']:,.0f}); every stage as "
            f"OpenCV: {'yes' if exact else 'NO'}; events as the reference: "
            f"{'yes' if ctx.results['events_equal'] else 'NO'}")


def summary(results, clock_mhz):
    frames = results["frames"]
    if not frames:
        return ["no frames ran"]
    memory = results["memory"]
    w, h = (round(640 * results["scale"]), round(480 * results["scale"]))
    return [
        f"{len(frames)} frames of {w}x{h} through the chain as ReconOS threads "
        f"({results['ppc']} px/clk, {clock_mhz:g} MHz)",
        f"chain alpha (camera publish to /cmd): {results['mean_cycles']:,.0f} cycles = "
        f"{results['mean_cycles'] / (clock_mhz * 1000):.3f} ms (sd {results['sd_cycles']:,.0f})",
        f"every stage as OpenCV: {'yes' if results['stages_bit_exact'] else 'NO'}; stop/start "
        f"events as the reference: {'yes' if results['events_equal'] else 'NO'}; "
        + (f"lane centre within {results['lane_centre_max_error_px']:.1f} px of the scene's"
           if results["lane_centre_max_error_px"] is not None else
           "no ground truth (frames from files or a bag)"),
        f"{results['cycles']:,} cycles in {results['cpu_seconds']:.0f} CPU-s; memory "
        f"{memory['peak'] / 2**20:.1f} MiB at most in use of {memory['size'] / 2**20:.0f} MiB",
    ]


ARGS = {
    "frames": SimArg("camera frames of the scene", 100, kind=int),
    "seed": SimArg("seed of the random scene", 1, kind=int),
    "red_from": SimArg("frame from which the traffic light is red (default: the scene's own)",
                       kind=int),
    "green_from": SimArg("frame from which the traffic light is green again", kind=int),
    "images": SimArg("camera frames from image files instead of the scene (comma-separated, "
                     "each at the chain's camera size; no ground truth)", files=True),
    "bad_frames": SimArg("1: first send each stage a frame it must drop", "0",
                         choices=("0", "1")),
}

NODES = [camera]
PLAY_NODES = [played_camera]
