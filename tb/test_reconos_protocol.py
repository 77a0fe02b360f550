# amaranth: UnusedElaboratable=no
"""rosgate's ReconOS tables against the literal values of docs/reconos.md (numbers copied from
the spec, not from hdl/reconos/protocol.py)."""

import pytest

from hdl.reconos.protocol import (
    CALLS,
    SIGNAL_THREAD_RESUME,
    SIGNAL_THREAD_START,
    Command,
    MemifOp,
    OsifRegister,
    ProcControlRegister,
    ResourceType,
    arch,
    call,
    memif_command,
    memif_decode,
    memif_split,
    osif_register_offset,
    proc_control_offset,
)

# docs/reconos.md, in table order
SPEC_CODES = {
    "THREAD_GET_INIT_DATA": 0x0A0, "THREAD_GET_STATE_ADDR": 0x0A1, "THREAD_EXIT": 0x0A2,
    "THREAD_YIELD": 0x0A3, "THREAD_CLEAR_SIGNAL": 0x0A4, "SEM_POST": 0x0B0, "SEM_WAIT": 0x0B1,
    "MUTEX_LOCK": 0x0C0, "MUTEX_UNLOCK": 0x0C1, "MUTEX_TRYLOCK": 0x0C2, "COND_WAIT": 0x0D0,
    "COND_SIGNAL": 0x0D1, "COND_BROADCAST": 0x0D2, "MBOX_GET": 0x0F0, "MBOX_PUT": 0x0F1,
    "MBOX_TRYGET": 0x0F2, "MBOX_TRYPUT": 0x0F3, "MEMORY_MALLOC": 0x0F4, "MEMORY_FREE": 0x0F5,
    "MEMORY_GETOBJADDR": 0x0F6, "MEMORY_GETMEMADDR": 0x0F7, "OSIF_INTERRUPTED": 0x0FF,
    "ROS_MESSAGE_SET_SIZE": 0x9F0, "ROS_PUBLISH": 0x900, "ROS_TAKE": 0x901,
    "ROS_TRYTAKE": 0x902, "ROS_TAKE_INTERRUPTABLE": 0x903,
    "ROS_TAKE_INTERRUPTABLE_CANCEL": 0x904, "ROS_SERVICES_RESPONSE": 0x910,
    "ROS_SERVICES_TRYTAKE": 0x911, "ROS_SERVICES_TAKE": 0x912, "ROS_ACTIONS_GOAL_TAKE": 0x920,
    "ROS_ACTIONS_GOAL_TRYTAKE": 0x921, "ROS_ACTIONS_GOAL_DECIDE": 0x922,
    "ROS_ACTIONS_RESULT_TAKE": 0x923, "ROS_ACTIONS_RESULT_TRYTAKE": 0x924,
    "ROS_ACTIONS_RESULT_SEND": 0x925, "ROS_ACTIONS_FEEDBACK": 0x926,
    "ROS_ACTIONS_CANCEL_TAKE": 0x927, "ROS_ACTIONS_CANCEL_TRYTAKE": 0x928,
    "ROS_ACTIONS_CANCEL_SEND": 0x929, "ROS_SERVICEC_REQUEST": 0x930,
    "ROS_SERVICEC_TRYTAKE": 0x931, "ROS_SERVICEC_TAKE": 0x932, "ROS_ACTIONC_GOAL_SEND": 0x940,
    "ROS_ACTIONC_GOAL_TRYTAKE": 0x941, "ROS_ACTIONC_GOAL_TAKE": 0x942,
    "ROS_ACTIONC_RESULT_SEND": 0x943, "ROS_ACTIONC_RESULT_TAKE": 0x944,
    "ROS_ACTIONC_RESULT_TRYTAKE": 0x945, "ROS_ACTIONC_FEEDBACK_TAKE": 0x946,
    "ROS_ACTIONC_FEEDBACK_TRYTAKE": 0x947, "ROS_ACTIONC_CANCEL_SEND": 0x948,
    "ROS_ACTIONC_CANCEL_TAKE": 0x949, "ROS_ACTIONC_CANCEL_TRYTAKE": 0x950,
}

# docs/reconos.md: command -> (argument words, reply words), defects 1-3 fixed
SPEC_WORDS = {
    0x0A0: (0, 1), 0x0A1: (0, 1), 0x0A2: (0, 0), 0x0A4: (0, 0), 0x0B0: (1, 1), 0x0B1: (1, 1),
    0x0C0: (1, 1), 0x0C1: (1, 1), 0x0C2: (1, 1), 0x0D0: (2, 1), 0x0D1: (1, 1), 0x0D2: (1, 1),
    0x0F0: (1, 1), 0x0F1: (2, 1), 0x0F2: (1, 2), 0x0F3: (2, 1), 0x0F4: (2, 1), 0x0F5: (1, 0),
    0x0F6: (1, 1), 0x0F7: (1, 1), 0x9F0: (4, 1), 0x900: (2, 1), 0x901: (2, 1), 0x902: (2, 2),
    0x912: (2, 1), 0x911: (2, 2), 0x910: (2, 1), 0x930: (2, 1), 0x932: (2, 1), 0x931: (2, 2),
    0x920: (2, 1), 0x921: (2, 2), 0x922: (2, 1), 0x923: (1, 1), 0x924: (1, 2), 0x925: (2, 1),
    0x926: (2, 1), 0x927: (1, 1), 0x928: (1, 1), 0x929: (1, 1), 0x940: (2, 1), 0x942: (1, 2),
    0x941: (1, 2), 0x943: (1, 1), 0x944: (2, 1), 0x945: (2, 2), 0x946: (2, 1), 0x947: (2, 1),
    0x948: (1, 1), 0x949: (1, 1), 0x950: (2, 1),
}


def test_command_codes_are_the_spec_table():
    assert {c.name: int(c) for c in Command} == SPEC_CODES
    assert SIGNAL_THREAD_START == 0x0100_0000 and SIGNAL_THREAD_RESUME == 0x0100_0001


def test_word_counts_of_every_call():
    for code, (nargs, nreplies) in SPEC_WORDS.items():
        c = call(code)
        assert c is not None, hex(code)
        assert (len(c.args), len(c.replies)) == (nargs, nreplies), (hex(code), c.method)
    # the yield flag is ignored by the dispatch
    assert call(0x8000_0901).command == Command.ROS_TAKE
    # the interruptible take writes its two handles and gets its reply later
    assert len(CALLS["ros_take_interruptable"].args) == 2
    assert not CALLS["ros_take_interruptable"].blocking


@pytest.mark.parametrize("name,stride,empty_msb", [("r64", 0x20, 63), ("r32", 0x10, 31)])
def test_osif_register_offsets(name, stride, empty_msb):
    assert [osif_register_offset(name, 0, r) for r in OsifRegister] == \
        [0, stride // 4, stride // 2, 3 * stride // 4]
    assert osif_register_offset(name, 3, OsifRegister.HW2SW_DATA) == 3 * stride
    assert arch(name).word_bits - 1 == empty_msb


def test_proc_control_offsets():
    r = ProcControlRegister
    assert [proc_control_offset("r64", x) for x in list(r)[:8]] == \
        [0x00, 0x08, 0x10, 0x18, 0x20, 0x28, 0x30, 0x38]
    r32 = [proc_control_offset("r32", x, 4) for x in (r.NUM_HWTS, r.PGD, r.FAULT_ADDR,
                                                      r.TLB_HITS, r.TLB_MISSES, r.SYS_RESET,
                                                      r.HWT_RESET, r.HWT_SIGNAL)]
    assert r32 == [0x00, 0x04, 0x08, 0x0C, 0x10, 0x14, 0x18, 0x1C]
    # 40 threads: two mask words each
    assert proc_control_offset("r32", r.HWT_SIGNAL, 40) == 0x18 + 8


def test_memif_command_format():
    assert memif_command("r32", MemifOp.WRITE, 0x100) == 0xF000_0100
    assert memif_command("r64", MemifOp.READ, 8) == 0x8
    assert memif_command("r64", MemifOp.WRITE, 256) == 0xF000_0000_0000_0100
    assert memif_decode("r64", 0xF000_0000_0000_0100) == (0xF0, 256)
    with pytest.raises(ValueError, match="24 bits"):
        memif_command("r32", MemifOp.READ, 1 << 24)


def test_split_rule():
    assert memif_split(0x1000, 8) == [(0x1000, 8)]
    assert memif_split(0x10F8, 16) == [(0x10F8, 8), (0x1100, 8)]
    assert memif_split(0x1040, 600) == [(0x1040, 192), (0x1100, 256), (0x1200, 152)]
    assert memif_split(0x2000, 0) == []


def test_resource_type_codes():
    assert {t.name.lower(): int(t) for t in ResourceType} == {
        "mbox": 0x1, "sem": 0x2, "mutex": 0x4, "cond": 0x8, "rosnode": 0x10, "rossub": 0x20,
        "rospub": 0x40, "rosmsg": 0x80, "rossrvs": 0x100, "rossrvc": 0x200,
        "rossrvmsgreq": 0x400, "rossrvmsgres": 0x800, "rosactions": 0x1000,
        "rosactionc": 0x2000, "rosactionmsggoalreq": 0x4000, "rostmr": 0x80000,
        "rosactionmsgresultres": 0x20000, "rosactionmsgfeedback": 0x40000, "mem": 0x100000}


def test_bad_parameters_name_the_value():
    from hdl.params import ParameterError
    from hdl.reconos import ReconosSystem
    from hdl.reconos.threads import EchoThread
    with pytest.raises(ParameterError, match="arch must be one of 'r32', 'r64', not 'r16'"):
        arch("r16")
    with pytest.raises(ParameterError, match="osif_depth must be a power of two"):
        ReconosSystem("r64", [EchoThread("r64", h_sub=0, h_pub=1, h_msg=2)], osif_depth=12)
    with pytest.raises(ValueError, match="slot 0 .*EchoThread.* r64"):
        ReconosSystem("r64", [EchoThread("r32", h_sub=0, h_pub=1, h_msg=2)])
