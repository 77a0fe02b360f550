"""rosidl C layouts (gen.msg.layout) against the spec's table and against real compilers.

The compilers see only the struct declarations of the generated header and compute
``offsetof``/``sizeof`` themselves; the constants are read from the assembly (nothing is
executed for the target).
"""

import re
import shutil
import subprocess
from pathlib import Path

import pytest

from gen.msg import MessageDefinitionError, MessageLibrary, parse_msg
from gen.msg.cheader import c_header
from gen.msg.layout import CLayout, c_identifier

ROOT = Path(__file__).resolve().parents[1]
COMPILERS = {"arm32": "arm-linux-gnueabihf-gcc", "arm64": "aarch64-linux-gnu-gcc",
             "x86_64": "gcc"}
CHECKED_TYPES = [
    "std_msgs/msg/Header", "std_msgs/msg/String", "sensor_msgs/msg/Image",
    "sensor_msgs/msg/PointCloud2", "rosgate_test_msgs/msg/AllPrimitives",
    "rosgate_test_msgs/msg/Nested", "rosgate_test_msgs/msg/Empty", "sorter_msgs/msg/Sortdata",
    "sorter_msgs/srv/Sort_Request", "sorter_msgs/srv/Sort_Response",
    "sorter_msgs/action/Sort_SendGoal_Request", "sorter_msgs/action/Sort_GetResult_Response",
    "sorter_msgs/action/Sort_FeedbackMessage", "mnist_msgs/srv/Mnist_Request",
]


@pytest.fixture(scope="module")
def library():
    return MessageLibrary([ROOT / "examples" / "messages"])


def offsets(library, arch, typename):
    return {path: offset for path, offset, _, _ in CLayout(library, arch).flat(typename)}


# docs/reconos.md, arm64 / arm32 columns
SPEC_TABLE = [
    ("std_msgs/msg/String", "data.data", 0, 0), ("std_msgs/msg/String", "data.size", 8, 4),
    ("std_msgs/msg/String", "data.capacity", 16, 8),
    ("std_msgs/msg/Header", "stamp.sec", 0, 0), ("std_msgs/msg/Header", "stamp.nanosec", 4, 4),
    ("std_msgs/msg/Header", "frame_id.data", 8, 8),
    ("sensor_msgs/msg/Image", "height", 32, 20), ("sensor_msgs/msg/Image", "width", 36, 24),
    ("sensor_msgs/msg/Image", "encoding.data", 40, 28),
    ("sensor_msgs/msg/Image", "encoding.size", 48, 32),
    ("sensor_msgs/msg/Image", "encoding.capacity", 56, 36),
    ("sensor_msgs/msg/Image", "is_bigendian", 64, 40), ("sensor_msgs/msg/Image", "step", 68, 44),
    ("sensor_msgs/msg/Image", "data.data", 72, 48), ("sensor_msgs/msg/Image", "data.size", 80, 52),
    ("sensor_msgs/msg/Image", "data.capacity", 88, 56),
    ("sorter_msgs/msg/Sortdata", "sortdata.data", 0, 0),
    ("sorter_msgs/msg/Sortdata", "sortdata.size", 8, 4),
    ("sorter_msgs/msg/Sortdata", "sortdata.capacity", 16, 8),
    ("sorter_msgs/srv/Sort_Request", "unsorted.data", 0, 0),
    ("sorter_msgs/srv/Sort_Response", "sorted.data", 0, 0),
    ("sorter_msgs/action/Sort_SendGoal_Request", "goal.unsorted.data", 16, 16),
    ("sorter_msgs/action/Sort_SendGoal_Request", "goal.unsorted.size", 24, 20),
    ("sorter_msgs/action/Sort_GetResult_Response", "result.sorted.data", 8, 4),
    ("sorter_msgs/action/Sort_GetResult_Response", "result.sorted.size", 16, 8),
    ("sorter_msgs/action/Sort_FeedbackMessage", "feedback.percent", 16, 16),
    ("mnist_msgs/srv/Mnist_Request", "rawdigit.data.data", 72, 48),
]


@pytest.mark.parametrize("typename,path,arm64,arm32", SPEC_TABLE,
                         ids=[f"{t.split('/')[-1]}.{p}" for t, p, _, _ in SPEC_TABLE])
def test_layout_matches_spec_table(library, typename, path, arm64, arm32):
    assert offsets(library, "arm64", typename)[path] == arm64
    assert offsets(library, "arm32", typename)[path] == arm32


def test_sizeof_matches_spec_table(library):
    for typename, arm64, arm32 in [("std_msgs/msg/String", 24, 12),
                                   ("std_msgs/msg/Header", 32, 20),
                                   ("sensor_msgs/msg/Image", 96, 60)]:
        assert CLayout(library, "arm64").struct(typename).size == arm64
        assert CLayout(library, "arm32").struct(typename).size == arm32


def compiled_constants(arch, source, workdir):
    """Compile ``source`` for ``arch`` to assembly; return the ints of ``rosgate_layout``."""
    compiler = shutil.which(COMPILERS[arch])
    if compiler is None:
        pytest.fail(f"{COMPILERS[arch]} missing: make setup installs gcc-arm-linux-gnueabihf "
                    "and gcc-aarch64-linux-gnu")
    cfile = workdir / f"layout_{arch}.c"
    cfile.write_text(source)
    asm = subprocess.run([compiler, "-S", "-O1", "-std=c11", "-ffreestanding", "-I", str(workdir), "-o", "-",
                          str(cfile)], capture_output=True, text=True)
    assert asm.returncode == 0, asm.stderr
    text = asm.stdout[asm.stdout.index("rosgate_layout:"):]
    values = []
    for line in text.splitlines()[1:]:
        mo = re.match(r"\s*\.(word|long|4byte)\s+(\d+)", line)
        if mo:
            values.append(int(mo.group(2)))
        elif re.match(r"\s*\.(size|section|text|data|ident)\b", line) or line.endswith(":"):
            break
    return values


@pytest.mark.parametrize("arch", list(COMPILERS))
def test_layout_equals_compiler(library, arch, tmp_path):
    """Every leaf offset and every sizeof equals what gcc computes for the generated structs."""
    expected, terms, headers = [], [], []
    for typename in CHECKED_TYPES:
        header = tmp_path / f"{c_identifier(typename)}.h"
        header.write_text(c_header(library, typename))
        headers.append(f'#include "{header.name}"')
        cname = c_identifier(typename)
        layout = CLayout(library, arch)
        terms.append(f"sizeof({cname})")
        expected.append(("sizeof", typename, layout.struct(typename).size))
        for path, offset, _, _ in layout.flat(typename):
            terms.append(f"offsetof({cname}, {path})")
            expected.append((path, typename, offset))
    # +1 keeps zeros out of the array (compilers may fold them into .zero/.space).
    source = "\n".join(headers) + "\n#include <stddef.h>\nconst unsigned int rosgate_layout[] = {\n" \
        + ",\n".join(f"  (unsigned int)({t}) + 1u" for t in terms) + "\n};\n"
    values = compiled_constants(arch, source, tmp_path)
    assert len(values) == len(expected), f"read {len(values)} constants, expected {len(expected)}"
    wrong = [(t, p, want, got - 1) for (p, t, want), got in zip(expected, values) if got - 1 != want]
    assert not wrong, f"{arch}: layout differs from gcc (type, path, rosgate, gcc): {wrong[:10]}"


def test_unknown_type_names_file_and_line(tmp_path):
    folder = tmp_path / "my_msgs" / "msg"
    folder.mkdir(parents=True)
    (folder / "Bad.msg").write_text("uint8 a\nNoSuchType b\n")
    with pytest.raises(MessageDefinitionError, match=r"Bad\.msg:2: unknown type "
                                                     r"\('my_msgs/msg/NoSuchType'\)"):
        MessageLibrary([tmp_path])


@pytest.mark.parametrize("text,message", [
    ("uint8[0] a\n", r":1: bad array bound: fixed arrays need N >= 1 \('uint8\[0\]'\)"),
    ("uint8 a\nuint8[<=0] b\n", r":2: bad array bound: need <=N, N >= 1"),
    ("uint8 a\nuint8 a\n", r":2: duplicate field name \('a'\)"),
    ("int32 Bad\n", r":1: field names are lower_case"),
    ("uint8[[ x\n", r":1: malformed type \('uint8\[\['\)"),
    ("uint8 x abc\n", r":1: bad value for uint8 \('abc'\)"),
    ("uint8\n", r":1: expected 'TYPE NAME'"),
])
def test_parse_errors_name_line_and_token(text, message):
    with pytest.raises(MessageDefinitionError, match=message):
        parse_msg(text, "p/msg/T", source="T.msg")


def test_cycle_is_reported(tmp_path):
    folder = tmp_path / "loop_msgs" / "msg"
    folder.mkdir(parents=True)
    (folder / "A.msg").write_text("B b\n")
    (folder / "B.msg").write_text("A a\n")
    with pytest.raises(MessageDefinitionError, match="type contains itself"):
        MessageLibrary([tmp_path])


def test_constants_defaults_and_comment_in_string(library):
    definition = library["rosgate_test_msgs/msg/AllPrimitives"]
    constants = {c.name: c.value for c in definition.constants}
    assert constants == {"MAX_COUNT": 10, "GREETING": "hello # not a comment"}
    defaults = {f.name: f.default for f in definition.fields if f.default is not None}
    assert defaults == {"u8": 7, "u32": 42}


def test_action_expansion(library):
    send_goal = library["sorter_msgs/action/Sort_SendGoal_Request"]
    assert [f.name for f in send_goal.fields] == ["goal_id", "goal"]
    assert str(send_goal.fields[0].type) == "unique_identifier_msgs/msg/UUID"
    result = library["sorter_msgs/action/Sort_GetResult_Response"]
    assert [(f.name, str(f.type)) for f in result.fields] == [
        ("status", "int8"), ("result", "sorter_msgs/action/Sort_Result")]
