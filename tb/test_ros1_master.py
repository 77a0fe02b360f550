"""The software ROS master (gen/ros1/master.py) over real XML-RPC on loopback, against the
Master API of docs/messages.md: every call answers ``[code, statusMessage, value]`` with
1 = SUCCESS and -1 = ERROR; registering a publisher returns the subscribers' APIs and sends
each subscriber ``publisherUpdate`` with the topic's publishers; unknown nodes and services
answer ERROR."""

import queue
import xmlrpc.client

import pytest

from host.ros1 import RosMaster
from host.ros1.master import XmlRpcServer

TOPIC = "/image_raw"
TYPE = "sensor_msgs/Image"


@pytest.fixture
def master():
    m = RosMaster("127.0.0.1", 0).start()
    yield m
    m.stop()


@pytest.fixture
def subscriber_node():
    """A node's slave API that records the ``publisherUpdate`` calls it receives."""
    updates = queue.Queue()
    server = XmlRpcServer("127.0.0.1", 0)

    def publisherUpdate(caller_id, topic, publishers):
        updates.put((caller_id, topic, publishers))
        return [1, "", 0]

    server.register_function(publisherUpdate, "publisherUpdate")
    server.start()
    yield server.uri, updates
    server.stop()


def test_master_api_register_lookup_unregister(master, subscriber_node):
    sub_api, updates = subscriber_node
    pub_api = "http://127.0.0.1:40001/"
    api = xmlrpc.client.ServerProxy(master.uri)

    assert api.registerSubscriber("/rcv", TOPIC, TYPE, sub_api) == [
        1, f"Subscribed to [{TOPIC}]", []]
    code, _, subs = api.registerPublisher("/snd", TOPIC, TYPE, pub_api)
    assert (code, subs) == (1, [sub_api])
    assert updates.get(timeout=5) == ("/master", TOPIC, [pub_api])

    assert api.lookupNode("/any", "/snd")[::2] == [1, pub_api]
    assert api.lookupNode("/any", "/rcv")[::2] == [1, sub_api]
    code, message, _ = api.lookupNode("/any", "/nobody")
    assert code == -1 and "/nobody" in message
    assert api.lookupService("/any", "/no_service")[0] == -1

    code, _, (pubs, subs, services) = api.getSystemState("/any")
    assert (code, pubs, subs, services) == (1, [[TOPIC, ["/snd"]]], [[TOPIC, ["/rcv"]]], [])
    assert api.getPublishedTopics("/any", "")[2] == [[TOPIC, TYPE]]

    # unregistering tells the subscriber that the topic has no publisher left
    assert api.unregisterPublisher("/snd", TOPIC, pub_api)[::2] == [1, 1]
    assert updates.get(timeout=5) == ("/master", TOPIC, [])
    assert api.unregisterPublisher("/snd", TOPIC, pub_api)[::2] == [1, 0]
    assert api.unregisterSubscriber("/rcv", TOPIC, sub_api)[::2] == [1, 1]
    assert api.getSystemState("/any")[2] == [[], [], []]
    assert updates.empty()
