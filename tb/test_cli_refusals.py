"""A first day's typos: each is refused with exit status 2 and a message naming the bad word
and what would have been accepted, before anything is built; paths a user types are read
against the folder the command was started in."""

import os
import shutil

import pytest

from .harness import ROOT, run_rosgate
from .models.image import IMAGES

SOBEL_DIP = ROOT / "examples" / "sobel_dip" / "build.cfg"
AV_CHAIN = ROOT / "examples" / "av_chain" / "build.cfg"
INVERSE = ROOT / "examples" / "inverse_kinematics"


def assert_refused(result, *words):
    assert result.returncode == 2, (result.returncode, result.stdout, result.stderr)
    assert "Traceback" not in result.stderr, result.stderr
    for word in words:
        assert word in result.stderr, (word, result.stderr)


@pytest.mark.parametrize("args, words", [
    (["--arg", "image=my_photo.png"], ["--arg image", "takes: images", "--help-args"]),
    (["--arg", "images"], ["--arg", "KEY=VALUE"]),
    (["--stall-ms", "-5"], ["--stall-ms", "'-5'"]),
    (["--limit-ms", "-1"], ["--limit-ms", "'-1'"]),
    (["--limit-ms", "nan"], ["--limit-ms", "'nan'"]),
    (["--ros2", "--service-queue", "0"], ["--service-queue", "'0': expected a whole number "
                                                             "above 0"]),
    (["--ros2", "--goal-policy", "later"], ["--goal-policy", "'later'"]),
    (["--ros2", "--clock", "gps"], ["--clock", "'gps'"]),
    (["--param", "Sobel.nosuch=1"], ["Sobel.nosuch=1", "no parameter 'nosuch'", "max_width"]),
    (["--param", "*.nosuch=1"], ["*.nosuch=1", "no thread has a parameter 'nosuch'"]),
    (["--param", "DIP.mode=reconros"], ["DIP.mode=reconros", "no parameter 'mode'"]),
    (["--param", "Sobel.max_width=abc"], ["max_width='abc' is not a whole number",
                                           "--param Sobel.max_width=abc", "build.cfg:"]),
    (["--record", "/proc/rosgate/bag"], ["--record /proc/rosgate/bag", "cannot create"]),
    (["-o", ROOT / "README.md"], ["-o", "a file, not a folder"]),
])
def test_sim_refuses_before_building(args, words, tmp_path):
    result = run_rosgate("sim", SOBEL_DIP, "--sim", "icarus", *args, cwd=tmp_path)
    assert_refused(result, *words)


def test_sim_refuses_a_value_its_argument_cannot_read(tmp_path):
    assert_refused(run_rosgate("sim", AV_CHAIN, "--arg", "frames=ten", cwd=tmp_path),
                   "--arg frames=ten", "'ten' is not a whole number")
    assert_refused(run_rosgate("sim", AV_CHAIN, "--arg", "bad_frames=yes", cwd=tmp_path),
                   "'yes' is not one of 0, 1")


def test_sim_refuses_an_optimisation_the_compiler_does_not_know(tmp_path):
    result = run_rosgate("sim", AV_CHAIN, cwd=tmp_path,
                         env=dict(os.environ, ROSGATE_CXX_OPT="-O9"))
    assert_refused(result, "ROSGATE_CXX_OPT must be one of -O0, -O1, -O2, -O3, -Os, -Og",
                   "'-O9'")


def test_help_args_lists_what_sim_py_declares():
    result = run_rosgate("sim", AV_CHAIN, "--help-args")
    assert result.returncode == 0, result.stderr
    for name in ("frames", "seed", "red_from", "green_from", "bad_frames"):
        assert f"  {name} " in result.stdout, result.stdout
    assert "default 100" in result.stdout


def test_parameter_without_parameters_line_blames_the_section_and_the_option(tmp_path):
    """inverse_kinematics' build.cfg has no Parameters: the error names the thread's section
    line and the --param it came from, not a Parameters line that does not exist."""
    result = run_rosgate("export-hw", INVERSE / "build.cfg", "-o", tmp_path / "out",
                         "--param", "Inverse.lanes=many")
    assert_refused(result, "[ReconosThread@Inverse]:", "--param Inverse.lanes=many",
                   "lanes='many' is not a whole number")
    assert "] Parameters:" not in result.stderr


def test_misspelt_section_kind_is_refused(tmp_path):
    shutil.copytree(INVERSE, tmp_path / "p")
    cfg = tmp_path / "p" / "build.cfg"
    cfg.write_text(cfg.read_text().replace("[HwSlot@", "[HwSlott@"))
    line = next(n for n, text in enumerate(cfg.read_text().splitlines(), 1)
                if text.startswith("[HwSlott@"))
    assert_refused(run_rosgate("info", cfg), f"build.cfg:{line}: [HwSlott@",
                   "unknown section")


def test_thread_folder_in_another_case_is_refused(tmp_path):
    shutil.copytree(INVERSE, tmp_path / "p")
    (tmp_path / "p" / "src" / "rt_inverse").rename(tmp_path / "p" / "src" / "rt_Inverse")
    result = run_rosgate("export-hw", tmp_path / "p" / "build.cfg", "-o", tmp_path / "out")
    assert_refused(result, "src/rt_Inverse/amaranth/thread.py", "rename the folder to "
                   "src/rt_inverse")
    assert not (tmp_path / "out" / "manifest.json").exists()


def test_binary_files_are_refused(tmp_path):
    binary = tmp_path / "binary"
    binary.write_bytes(bytes(range(256)) * 4)
    assert_refused(run_rosgate("info", binary), "not a text file", "build.cfg is an INI")
    assert_refused(run_rosgate("export", "finemb", "--io", binary, "-o", tmp_path / "out"),
                   "not a text file", "IO description is TOML")


@pytest.mark.parametrize("folder, word", [("/nonexistent/rosgate", "no such folder"),
                                          (ROOT / "README.md", "a file, not a folder")])
def test_msg_dir_must_be_a_folder(folder, word):
    assert_refused(run_rosgate("msg", "show", "std_msgs/String", "--msg-dir", folder),
                   f"--msg-dir {folder}", word)


def test_paths_are_read_against_the_callers_folder(tmp_path):
    """``cd ~/photos && rosgate sim <repo>/examples/sobel_dip/build.cfg --arg images=mine.png
    -o out --trace trace.txt``: every path is the caller's."""
    photos = tmp_path / "photos"
    photos.mkdir()
    shutil.copy(IMAGES / "chelsea_96x72.png", photos / "mine.png")
    result = run_rosgate("sim", SOBEL_DIP, "--sim", "icarus", "--arg", "images=mine.png",
                         "-o", "out", "--trace", "trace.txt", cwd=photos)
    assert result.returncode == 0, result.stderr
    assert (photos / "out" / "mine_filtered.png").is_file()
    assert (photos / "trace.txt").stat().st_size > 0
    assert "1 of 1 images equal to OpenCV" in result.stdout


BAD_THREADS = {
    "syntax": ("def build(ctx) return 1\n", 1, "SyntaxError: expected ':'"),
    "no_build": ("x = 1\n", 1, "defines no build(ctx) function"),
    "undefined_state": ('''from amaranth import Module
from amaranth.lib import wiring


class Bad(wiring.Component):
    def elaborate(self, platform):
        m = Module()
        with m.FSM():
            with m.State("A"):
                m.next = "NOPE"
        return m


def build(ctx):
    return Bad(ctx.thread_signature())
''', 8, "FSM state 'NOPE' is referenced but not defined"),
    "comb_loop": ('''from amaranth import Module, Signal
from amaranth.lib import wiring


class Bad(wiring.Component):
    def elaborate(self, platform):
        m = Module()
        a, b = Signal(), Signal()
        m.d.comb += a.eq(~b)
        m.d.comb += b.eq(a)
        m.d.comb += self.osif_hw2sw.data.eq(a)
        return m


def build(ctx):
    return Bad(ctx.thread_signature())
''', 9, "CombinationalCycle"),
    "missing_port": ('''from amaranth.lib import wiring


class Bad(wiring.Component):
    def elaborate(self, platform):
        pass


def build(ctx):
    members = dict(ctx.thread_signature().members)
    del members["osif_sw2hw"]
    return Bad(wiring.Signature(members))
''', 9, "without the port 'osif_sw2hw' the thread needs: Out(FifoReadSignature: data, "
        "empty, re); it has none"),
    "undefined_name": ("def build(ctx):\n    return undefined_name\n", 2,
                       "NameError: name 'undefined_name' is not defined"),
}


@pytest.mark.parametrize("kind", BAD_THREADS)
@pytest.mark.parametrize("command", ["export-hw", "sim"])
def test_errors_in_thread_code_name_file_and_line(kind, command, tmp_path):
    source, line, words = BAD_THREADS[kind]
    shutil.copytree(INVERSE, tmp_path / "p")
    thread = tmp_path / "p" / "src" / "rt_inverse" / "amaranth" / "thread.py"
    thread.write_text(source)
    extra = ["-o", tmp_path / "out"] if command == "export-hw" else ["--sim", "icarus"]
    result = run_rosgate(command, tmp_path / "p" / "build.cfg", *extra, cwd=tmp_path)
    assert_refused(result, f"{thread}:{line}: ", words)
    assert "UnusedElaboratable" not in result.stderr and "0x" not in result.stderr
    assert len(result.stderr.strip().splitlines()) <= 4, result.stderr
