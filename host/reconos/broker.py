"""An in-process ROS graph: topics, services and actions for hardware threads (through the
ReconOS runtime model) and the Python nodes of a project's ``sim.py``."""

import collections

from cocotb.triggers import Event

__all__ = ["Broker", "ActionGoal", "Queue"]


class Broker:
    """An in-process ROS graph: topics with any number of publishers and subscribers, and
    services. Python nodes subscribe with :meth:`subscribe` (a queue) and publish with
    :meth:`publish`; services are Python callables or hardware servers."""

    def __init__(self):
        self._subs = collections.defaultdict(list)
        self._services = {}
        self._actions = {}
        #: publications, calls and goals so far (a measure of progress)
        self.events = 0
        #: ``observer(topic, value)`` is called for every publication (recorders)
        self.observers = []
        #: a subscription keeps at most this many messages, dropping the oldest (ROS 2's
        #: keep-last history); ``None``: every message (the default of an in-process graph,
        #: whose nodes pace themselves)
        self.history = None

    def subscribe(self, topic, origin=None):
        """A queue of the values published on ``topic``; with an ``origin``, not those
        published with the same origin (ROS 2's ``ignore_local_publications``)."""
        q = Queue(history=self.history)
        q.origin = origin
        self._subs[topic].append(q)
        return q

    def publish(self, topic, value, origin=None):
        self.events += 1
        for observe in self.observers:
            observe(topic, value)
        for q in self._subs[topic]:
            if origin is None or q.origin != origin:
                q.put(value)

    def serve(self, service, server):
        """Register a server: a :class:`Queue` of ``(request, reply_queue)`` pairs."""
        self._services[service] = server

    def server_queue(self, service):
        """The request queue of a hardware server of ``service``: every slot serving it takes
        from the same queue (as ReconROS' threads share one rcl service), so two slots serve
        two calls at once; each keeps the reply queue of the request it took."""
        q = self._services.get(service)
        if not isinstance(q, Queue):
            q = self._services[service] = Queue()
        return q

    async def call(self, service, request):
        """Call a service; return the response value."""
        reply = Queue()
        self.events += 1
        if service not in self._services:
            raise KeyError(f"no server for service {service!r} (servers: "
                           f"{', '.join(sorted(self._services)) or 'none'})")
        self._services[service].put((request, reply))
        return await reply.get()

    def action_server_queue(self, action):
        """Register an action server: a :class:`Queue` of :class:`ActionGoal`, shared by every
        slot that serves ``action``."""
        q = self._actions.get(action)
        if not isinstance(q, Queue):
            q = self._actions[action] = Queue()
        return q

    def send_goal(self, action, goal, goal_id=None):
        """Send a goal (the ``goal`` part of ``<Action>_SendGoal_Request``) to ``action``;
        return its :class:`ActionGoal` (acceptance, feedback and result queues)."""
        self.events += 1
        if action not in self._actions:
            raise KeyError(f"no server for action {action!r} (servers: "
                           f"{', '.join(sorted(self._actions)) or 'none'})")
        g = ActionGoal(goal, goal_id if goal_id is not None else bytes(range(16)))
        self._actions[action].put(g)
        return g

    def withdraw_goal(self, action, goal):
        """Take ``goal`` back out of ``action``'s queue before a server took it; whether it
        was still there."""
        queue = self._actions.get(action)
        if queue is None or goal not in queue.items:
            return False
        queue.items.remove(goal)
        return True


class ActionGoal:
    """One goal of an action, as both ends see it (rclc's goal handle).

    ``accepted`` receives the server's decision (a bool); :meth:`request_result` is the
    client's ``get_result`` request, which the server's ACTIONS_RESULT_TAKE waits for;
    :meth:`cancel` the client's cancel request, which the server's ACTIONS_CANCEL_TAKE waits
    for and ACTIONS_CANCEL_TRYTAKE sees; ``feedback`` receives ``<Action>_FeedbackMessage``
    values; ``result`` the ``<Action>_GetResult_Response`` value (with ``status``).
    """

    def __init__(self, goal, goal_id):
        self.goal_id = bytes(goal_id)
        self.request = {"goal_id": {"uuid": list(self.goal_id)}, "goal": goal}
        self.accepted = Queue()
        self.feedback = Queue()
        self.result = Queue()
        self.result_requested = Event()
        self.cancel_requested = Event()

    def request_result(self):
        self.result_requested.set()

    def cancel(self):
        self.cancel_requested.set()


class Queue:
    """A FIFO for coroutines: unbounded, or bounded by ``maxsize`` (``put_wait`` waits,
    ``put_nowait`` refuses), or keeping the last ``history`` items (``put`` drops the oldest,
    counted in ``dropped``)."""

    def __init__(self, maxsize=0, history=None):
        self.items = collections.deque()
        self.maxsize = maxsize
        self.history = history
        self.dropped = 0
        self._event = Event()
        self._space = Event()

    def put_nowait(self, item):
        if self.maxsize and len(self.items) >= self.maxsize:
            return False
        self.put(item)
        return True

    def put(self, item):
        if self.history is not None and len(self.items) >= self.history:
            self.items.popleft()
            self.dropped += 1
        self.items.append(item)
        self._event.set()

    async def put_wait(self, item):
        while self.maxsize and len(self.items) >= self.maxsize:
            self._space.clear()
            await self._space.wait()
        self.put(item)

    def get_nowait(self):
        if not self.items:
            return None
        item = self.items.popleft()
        self._space.set()
        return item

    async def get(self):
        while not self.items:
            self._event.clear()
            await self._event.wait()
        item = self.items.popleft()
        self._space.set()
        return item

    def __len__(self):
        return len(self.items)
