"""ReconROS build.cfg parsing (docs/reconos.md, docs/topics.md): the spec's handle examples,
every example project, and one clear error (file, line, section, key) per kind of bad input."""

import threading
import types

import pytest

from gen.config import ConfigError, Location, load_project, parse_project
from gen.system import _load
from hdl.reconos.protocol import ResourceType
from host.cli import main as rosgate

from .harness import ROOT
from .projects import EXAMPLES


def handles(project, thread):
    t = next(t for t in project.threads if t.name == thread)
    return {r.name: h for h, r in enumerate(t.resources)}


def test_spec_handle_examples():
    """Handle numbering (docs/build-cfg.md): the Sobel server app's Video group -> 0..4; the
    sort service demo -> Address 0,
    Acknowledge 1, sort_srv_res 2, sort_srv_req 3, node_1 4, srv 5."""
    sobel = load_project(ROOT / "examples/sobel_topic/build.cfg")
    assert handles(sobel, "Sobel") == {"image_msg": 0, "image_msg_out": 1, "node_1": 2,
                                       "SubData": 3, "PubData": 4}
    assert [r.c_name for r in sobel.threads[0].resources][4] == "video_pubdata"
    sort = load_project(ROOT / "examples/sort_service/build.cfg")
    assert handles(sort, "SortDemo") == {"Address": 0, "Acknowledge": 1, "sort_srv_res": 2,
                                         "sort_srv_req": 3, "node_1": 4, "srv": 5}
    t = sort.threads[0]
    assert [s.name for s in t.slots] == ["SortDemo(0)", "SortDemo(1)"]
    assert [s.id for s in t.slots] == [0, 1] and t.slots[0].clock.freq == 120_000_000
    assert [r.type_code for r in t.resources] == [
        ResourceType.MBOX, ResourceType.MBOX, ResourceType.ROSSRVMSGRES,
        ResourceType.ROSSRVMSGREQ, ResourceType.ROSNODE, ResourceType.ROSSRVS]
    assert [r.id for r in t.resources] == list(range(128, 134))
    assert t.resources[2].msgtype == "my_reconros_services/srv/Sort_Response"
    assert any("rossrvs without a service name" in w for w in sort.warnings)


def test_listing1_and_gateway_topology():
    """The paper's Listing 1 (two groups sharing a service message name) and docs/topics.md's
    gateway demo: nicehwtopic has publishers Threadb + Gateway1 (``_out``) and subscribers
    Threada + Gateway1 (``_in``): N_TO_M; hardware-topic endpoints have no handle."""
    p = load_project(ROOT / "examples/sobel_dip/build.cfg")
    assert handles(p, "Sobel") == {"node_3": 0, "filter_service_msg_res": 1,
                                   "filter_service_msg_req": 2, "filter_server": 3}
    assert handles(p, "DIP") == {"node_2": 0, "filter_service_msg_res": 1,
                                 "filter_service_msg_req": 2, "filter_client": 3,
                                 "image_msg": 4, "sub": 5, "pub": 6}
    g = load_project(ROOT / "examples/hwtopic_gateway/build.cfg")
    topic = g.topics["nicehwtopic"]
    assert topic.topology == "N_TO_M"
    assert [(e.thread.name, e.port) for e in topic.pubs] == [("Threadb", "nicehwtopic"),
                                                             ("Gateway1", "nicehwtopic_out")]
    assert [(e.thread.name, e.port, e.depth) for e in topic.subs] == [
        ("Threada", "nicehwtopic", 64), ("Gateway1", "nicehwtopic_in", 0)]
    assert handles(g, "Threada") == {"debug_mbox": 0, "img_output": 1, "node_1": 2,
                                     "PubData": 3}
    assert handles(g, "Gateway1") == {"node": 0, "msg_in": 1, "msg_out": 2, "pub": 3,
                                      "sub": 4}
    assert [t.id for t in g.threads] == [0, 1, 2] and g.threads[2].gateway["sw_topic"] == \
        "/topic/gateway"


def test_group_ranges_and_percent():
    """``[ResourceGroup@G(a:b)]`` makes G_a..G_b with ``%`` replaced; ``ResourceGroup =
    G(a:b)`` on a thread takes them all; a 4-argument rosmsg and the U_Int32 quirk."""
    text = BASE.replace("[ResourceGroup@Res]", "[ResourceGroup@Res(1:2)]").replace(
        'node_1 = rosnode, "n"', 'node_1 = rosnode, "n%"\nbox = mbox, 1%\n'
        'num = rosmsg, std_msgs, msg, U_Int32\nseq = rosmsg, std_msgs, msg, U_Int32, 8').replace(
        "ResourceGroup = Res", "ResourceGroup = Res(1:2)")
    p = parse_project(text, "x.cfg")
    t = p.threads[0]
    assert [(r.group, r.name) for r in t.resources][:4] == [
        ("Res_1", "node_1"), ("Res_1", "box"), ("Res_1", "num"), ("Res_1", "seq")]
    assert t.resources[0].args == ['"n1"'] and t.resources[1].args == ["11"]
    assert t.resources[7 + 1].args == ["12"] and t.resources[2].msgtype == "std_msgs/msg/UInt32"
    assert len(t.resources) == 2 * 7


BASE = """\
[General]
Name = T
TargetBoard = zcu104,0
TargetPart = xczu7ev-ffvc1156-2-e
ReferenceDesign = timer
TargetOS = linux64
TargetXil = vivado,2021.2
SystemClock = System

[Clock@System]
ClockSource = static
ClockFreq = 100000000

[HwSlot@S(0:1)]
Id = 0
Clock = System

[ResourceGroup@Res]
node_1 = rosnode, "n"
img = rosmsg, sensor_msgs, msg, Image
sub = rossub, node_1, img, "/in", 10000
pub = rospub, node_1, img, "/out"

[ReconosThread@A]
Slot = S(0)
HwSource = hls
ResourceGroup = Res
"""

#: (what, edit of BASE, line, section, key, words the message must contain)
BAD = [
    ("unknown resource type", ("pub = rospub", "pub = rospublisher"), 22, "ResourceGroup@Res",
     "pub", ["unknown resource type 'rospublisher'", "rospub"]),
    ("handle to an undefined node", ('"/out"', '"/out"\nsub2 = rossub, node_9, img, "/x", 5'),
     23, "ResourceGroup@Res", "sub2", ["'node_9'", "rosnode", "not defined"]),
    ("message argument of the wrong type", ('pub = rospub, node_1, img', 'pub = rospub, node_1, '
                                                                        'node_1'),
     22, "ResourceGroup@Res", "pub", ["'node_1'", "rosmsg", "a rosnode resource"]),
    ("slot glob that matches nothing", ("Slot = S(0)", "Slot = Q(*)"), 25, "ReconosThread@A",
     "Slot", ["matches no slot", "S(0), S(1)"]),
    ("hw topic without subscriber", ('"/out"', '"/out"\nhp = rospub, node_1, sensor_msgs/Image,'
                                               ' "t", hw'),
     23, "ResourceGroup@Res", "hp", ["'t'", "no subscriber"]),
    ("hw topic without publisher", ('"/out"', '"/out"\nhs = rossub, node_1, sensor_msgs/Image,'
                                               ' "t", hw, 64'),
     23, "ResourceGroup@Res", "hs", ["'t'", "no publisher"]),
    ("hw FIFO depth not a power of two", ('"/out"', '"/out"\nhs = rossub, node_1, '
                                                    'sensor_msgs/Image, "t", hw, 48'),
     23, "ResourceGroup@Res", "hs", ["power of two", "48"]),
    ("missing message definition", ("sensor_msgs, msg, Image", "nav_stuff, msg, Mystery"),
     20, "ResourceGroup@Res", "img", ["nav_stuff/msg/Mystery", "not defined"]),
    ("unknown section", ("[ReconosThread@A]", "[Thread@A]"), 24, "Thread@A", None,
     ["unknown section", "ReconosThread@N"]),
    ("unknown key", ("HwSource = hls", "HwSauce = hls"), 26, "ReconosThread@A", "HwSauce",
     ["unknown key", "HwSource"]),
    ("missing required key", ("SystemClock = System\n", ""), 1, "General", None,
     ["missing required key 'SystemClock'"]),
    ("duplicate key", ("Id = 0\n", "Id = 0\nId = 1\n"), 16, "HwSlot@S(0:1)", "Id",
     ["defined twice", "line 15"]),
    ("bad clock frequency", ("ClockFreq = 100000000", "ClockFreq = 100MHz"), 12, "Clock@System",
     "ClockFreq", ["integer", "'100MHz'"]),
    ("slot on an undefined clock", ("Clock = System\n\n[Res", "Clock = Fast\n\n[Res"), 16,
     "HwSlot@S(0:1)", "Clock", ["[Clock@Fast]"]),
    ("slot section without a range", ("[HwSlot@S(0:1)]", "[HwSlot@S]"), 14, "HwSlot@S", None,
     ["slot range"]),
    ("undefined resource group", ("ResourceGroup = Res\n", "ResourceGroup = Rez\n"), 27,
     "ReconosThread@A", "ResourceGroup", ["'Rez'", "Res"]),
    ("two threads in one slot", ("ResourceGroup = Res\n", "ResourceGroup = Res\n\n"
                                 "[ReconosThread@B]\nSlot = S(0)\n"), 29, "ReconosThread@B",
     "Slot", ["already taken by thread A"]),
    ("partial reconfiguration", ("SystemClock = System\n", "SystemClock = System\n"
                                 "PartialReconfiguration = true\n"), 9, "General",
     "PartialReconfiguration", ["not supported"]),
    ("board and OS disagree", ("TargetOS = linux64", "TargetOS = linux"), 6, "General",
     "TargetOS", ["r32", "zcu104", "r64"]),
    ("too few arguments", ('img = rosmsg, sensor_msgs, msg, Image', 'img = rosmsg, sensor_msgs'),
     20, "ResourceGroup@Res", "img", ["rosmsg takes", "1 argument"]),
    ("bad mbox size", ('"/out"', '"/out"\nbox = mbox, lots'), 23, "ResourceGroup@Res", "box",
     ["mbox size", "'lots'"]),
    ("hw service without its interface", ('"/out"', '"/out"\nsrv = rossrvs, node_1, img, '
                                                    '"sort", hw'),
     23, "ResourceGroup@Res", "srv", ["'img'", "rossrvmsg", "a rosmsg resource"]),
    ("hw service: hw in the wrong place", ('"/out"', '"/out"\nsm = rossrvmsg, my, srv, S\n'
                                                     'srv = rossrvs, node_1, sm, hw, "sort"'),
     24, "ResourceGroup@Res", "srv", ["\"name\", hw", "docs/services.md"]),
    ("hw service FIFO depth", ('"/out"', '"/out"\nsm = rossrvmsg, my, srv, S\n'
                                         'srv = rossrvc, node_1, sm, "sort", hw, 3'),
     24, "ResourceGroup@Res", "srv", ["power of two", "3"]),
    ("hw service with no server", ('"/out"', '"/out"\nsm = rossrvmsg, std_srvs, srv, Trigger\n'
                                             'srv = rossrvc, node_1, sm, "sort", hw'),
     24, "ResourceGroup@Res", "srv", ["'sort_request'", "no subscriber"]),
    ("hw action of an undefined interface", ('"/out"', '"/out"\nam = rosactionmsg, nav, action, '
                                                       'Drive\nas = rosactions, node_1, am, '
                                                       '"drive", hw\nac = rosactionc, node_1, '
                                                       'am, "drive", hw'),
     23, "ResourceGroup@Res", "am", ["nav/action/Drive", "not defined"]),
    ("gateway with keys of two kinds", ("ResourceGroup = Res\n", "ResourceGroup = Res\n\n"
                                        "[ROSGateway@G]\nSlot = S(1)\nHWTopic = t\n"
                                        "SWService = /s\n"),
     29, "ROSGateway@G", None, ["one topic, service or action", "topic and service"]),
    ("service gateway without its type", ("ResourceGroup = Res\n", "ResourceGroup = Res\n\n"
                                          "[ROSGateway@G]\nSlot = S(1)\nHWService = sort\n"
                                          "SWService = /sort\n"),
     29, "ROSGateway@G", None, ["missing required key 'SrvType'", "HWService, SWService"]),
    ("action gateway type not pkg/Type", ("ResourceGroup = Res\n", "ResourceGroup = Res\n\n"
                                          "[ROSGateway@G]\nSlot = S(1)\nHWAction = a\n"
                                          "SWAction = /a\nActionType = x/action/Y\n"),
     33, "ROSGateway@G", "ActionType", ["expected 'pkg/Type'", "x/action/Y"]),
]


@pytest.mark.parametrize("what,edit,line,section,key,words", BAD, ids=[b[0] for b in BAD])
def test_bad_config(tmp_path, what, edit, line, section, key, words):
    old, new = edit
    assert old in BASE, what
    path = tmp_path / "build.cfg"
    path.write_text(BASE.replace(old, new, 1))
    with pytest.raises(ConfigError) as info:
        load_project(path)
    err = info.value
    assert (err.location.file, err.location.line, err.location.section, err.location.key) == \
        (str(path), line, section, key), str(err)
    for w in words:
        assert w in err.message, f"{what}: {w!r} not in {err.message!r}"


def test_hw_service_and_action_topics(tmp_path):
    """``rossrvs``/``rossrvc``/``rosactions``/``rosactionc`` ending in ``hw`` become the
    ``<name>_request`` and ``<name>_reply`` hardware topics, clients publishing requests,
    the server replies, with the subscriber FIFO depth on the subscribing side."""
    text = BASE.replace('"/out"', '"/out"\nsm = rossrvmsg, std_srvs, srv, Trigger\n'
                                  'srv = rossrvs, node_1, sm, "/check", hw, 16\n'
                                  'cli = rossrvc, node_1, sm, "/check", hw, 32', 1)
    path = tmp_path / "build.cfg"
    path.write_text(text)
    p = load_project(path, check=False)     # the message store has no services
    request, reply = p.topics["check_request"], p.topics["check_reply"]
    assert request.msgtype == reply.msgtype == "std_srvs/srv/Trigger"
    assert [(e.key, e.direction, e.depth, e.port) for e in request.pubs + request.subs] == \
        [("cli", "pub", 0, "check_request_out"), ("srv", "sub", 16, "check_request_in")]
    assert [(e.key, e.direction, e.depth) for e in reply.pubs + reply.subs] == \
        [("srv", "pub", 0), ("cli", "sub", 32)]
    assert all(e.interface == "std_srvs/srv/Trigger" for e in p.threads[0].endpoints)
    example = load_project(ROOT / "examples/hw_services/build.cfg")
    assert sorted(example.topics) == ["fibonacci_reply", "fibonacci_request", "sort_reply",
                                      "sort_request"]
    assert [e.thread.name for e in example.topics["sort_request"].pubs] == \
        ["SortClientA", "SortClientB", "SortGateway"]
    assert [e.thread.name for e in example.topics["fibonacci_reply"].subs] == \
        ["FibClientA", "FibClientB", "FibGateway"]
    gateway = next(t for t in example.threads if t.name == "SortGateway")
    assert gateway.gateway == {"kind": "service", "sw_service": "/sort", "hw_service": "sort",
                               "srvtype": "my_reconros_services/srv/Sort"}
    assert [(r.key, r.type) for r in gateway.resources] == [
        ("node", "rosnode"), ("srv_msg", "rossrvmsgres"), ("srv_msg", "rossrvmsgreq"),
        ("srvs", "rossrvs")]


def test_base_config_is_good(tmp_path):
    path = tmp_path / "build.cfg"
    path.write_text(BASE)
    p = load_project(path)
    assert [t.name for t in p.threads] == ["A"] and p.slots[1].thread is None


def test_cli_reports_config_errors(tmp_path, capsys):
    path = tmp_path / "build.cfg"
    path.write_text(BASE.replace("rospub", "rospubb"))
    assert rosgate(["info", str(path)]) == 2
    err = capsys.readouterr().err
    assert f"{path}:22: [ResourceGroup@Res] pub: unknown resource type 'rospubb'" in err


@pytest.mark.parametrize("example", EXAMPLES)
def test_examples_parse(example, capsys):
    """Every example project parses and ``rosgate info`` describes it."""
    assert rosgate(["info", str(ROOT / "examples" / example / "build.cfg")]) == 0
    out = capsys.readouterr().out
    assert "slots:" in out and "threads:" in out and "handle  0" in out


def test_thread_module_loads_once_across_threads(tmp_path):
    """Two systems built side by side (the chain bench simulates two in threads) load a
    thread's Amaranth module once; neither gets it half executed, without its build()."""
    path = tmp_path / "thread.py"
    # the module takes a while to execute, so the second load comes while the first runs
    path.write_text("import time\ntime.sleep(0.3)\n\n\ndef build(ctx):\n    return None\n")
    thread = types.SimpleNamespace(core_name="rt_slow",
                                   where=Location("build.cfg", 1, "HwThread@Slow"))
    results, errors = [], []

    def load():
        try:
            module = _load(path, thread)
            # what build_thread does next
            results.append((module, callable(getattr(module, "build", None))))
        except Exception as exc:      # noqa: BLE001 - reported by the assertion below
            errors.append(exc)
    workers = [threading.Thread(target=load) for _ in range(3)]
    for worker in workers:
        worker.start()
    for worker in workers:
        worker.join()
    assert not errors, errors
    assert len(results) == 3 and all(module is results[0][0] for module, _ in results)
    assert all(has_build for _, has_build in results), results
