"""``recorder``: records topics into a rosbag2 bag (the thin ROS layer over the core).

Run it with ``ros2 run dam_recorder recorder -o DIR [topics...]`` (``--help`` lists the
options; each is also a parameter below). The node finds and subscribes to the topics and
answers the services; what it takes goes to the writing pipeline
(:class:`~dam_recorder.writing.BagWriting`: the backlog, the bag, the losses) and, in episode
mode, the goal events to :class:`~dam_recorder.episode_events.EpisodeEvents`.

Parameters (all read-only)
--------------------------
output : string
    Bag directory to create; empty: ``rosbag2_<YYYY_MM_DD-HH_MM_SS>`` in the working directory.
storage : string
    ``mcap`` (default) or ``sqlite3``.
compression : string
    MCAP chunk compression ``zstd`` or ``none``; empty: ``zstd`` for MCAP, ``none`` for sqlite3.
topics : string[]
    Topics recorded by name (default: :data:`~dam_recorder.selection.DEFAULT_TOPICS`); ``['']``
    names none (then ``regex`` alone selects).
regex, exclude : string
    Also record the topics ``regex`` matches; never those ``exclude`` matches (empty: none).
max_bag_size : int [bytes], max_bag_duration : double [s]
    No storage file is larger than ``max_bag_size`` once closed (a new file starts before a
    message that could take it over, :mod:`~dam_recorder.file_size`); a new file starts at
    this time span; 0: no limit.
chunk_interval : double [s]
    Longest time a received message waits in memory before it is in the file.
discovery_period : double [s]
    How often the recorder looks for new topics and publishers.
queue_depth : int [messages]
    Depth of each subscription's queue (default 5000: 10 s of a 500 Hz topic, a recorder
    that falls behind for a while loses nothing).
max_backlog_bytes : int [bytes]
    Most memory the messages waiting to be written may take (default 256 MiB); beyond it
    messages are dropped and counted per topic, never the goal's events and statuses.
stop_write_time : double [s]
    After SIGINT or SIGTERM, how long the recorder goes on writing what it received (default
    2); the rest is counted per topic as not written.
episodes : bool
    Episode mode: one bag per ``/dam_grasp`` goal in the directory ``output``
    (:mod:`~dam_recorder.episodes`), from ``pre_roll`` before the goal to ``post_roll`` after.
pre_roll, post_roll : double [s]
    What an episode holds before its goal starts and after it ends.

Messages are taken serialized (``raw=True``: never deserialized), cut at their CDR end
(:mod:`~dam_recorder.cdr_end`) and logged at their header stamp when their type starts with a
``std_msgs/Header``, else at the time the middleware received them (on the simulated clock
with ``use_sim_time:=true``, :mod:`~dam_recorder.clock_receipts`). Services
(``std_srvs/srv/Trigger``): ``~/pause``, ``~/resume``, ``~/split``. SIGINT and SIGTERM close
the bag (``destroy_node``) within ``stop_write_time`` of writing; the closing line and the
bag's metadata count every message and name every selected topic not recorded
(:mod:`~dam_recorder.recorded_topics`).

The first error writing the bag (a full or read-only file system, the bag directory removed,
an I/O error; :mod:`~dam_recorder.write_failure`) is logged once, naming the bag, the file and
the errno; the bag is closed with what is on disk, every message not written is counted
(``dam_recorder.unwritten_messages``, and in the last log line) and the recorder stops by
itself with status :data:`~dam_recorder.write_failure.WRITE_ERROR_STATUS` (74), also when a
SIGINT or SIGTERM comes meanwhile.

The recorder runs with the normal scheduling policy, never ``SCHED_FIFO``: real-time threads
of a job that has no deadline (a recorder, like the analysis server and the controller) count
against the kernel's real-time budget, and once that runs out the kernel stops every
real-time thread of the machine for the rest of the period (``docs/recording.md``, "Keeping
up"). It counts what it could not record instead: gaps in each publisher's sequence numbers
(``dam_recorder.dropped_messages``), and how far behind the middleware's receipt it writes
(``dam_recorder.backlog``, :mod:`~dam_recorder.backlog`).
"""

from __future__ import annotations

import os
import sys
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor
from rclpy.impl.implementation_singleton import rclpy_implementation as _rclpy
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from rclpy.task import Future
from rclpy.utilities import remove_ros_args
from rosgraph_msgs.msg import Clock
from std_srvs.srv import Trigger

from dam_common.clock import create_steady_timer
from dam_common.node import run_node
from dam_common.service_qos import SERVICE_QOS
from dam_common.shutdown import SHUTDOWN
from dam_common.words import counted
from dam_recorder.bag_writer import CHUNK_INTERVAL_RANGE_S, MIN_SPLIT_BYTES, BagWriter
from dam_recorder.cdr_end import CdrEnd
from dam_recorder.cli import parameter_overrides
from dam_recorder.clock_receipts import clock_ns_of
from dam_recorder.completeness import (
    COUNTED_TOPICS,
    DIAGNOSTICS_TOPIC,
    FACT_TYPES,
    Facts,
    diagnostic_counts,
    header_stamp_ns,
)
from dam_recorder.episode_events import EpisodeEvents
from dam_recorder.episode_messages import EPISODE_TOPIC
from dam_recorder.episodes import EpisodeRecorder, TopicSpec
from dam_recorder.errors import BagWriteError, ConfigurationError, DamRecorderError
from dam_recorder.qos import request_for_offers, to_rosbags_qos
from dam_recorder.recorded_topics import PROTECTED_TOPICS, RecordedTopic
from dam_recorder.ros_types import message_class, offered_qos, starts_with_header
from dam_recorder.selection import DEFAULT_TOPICS, TopicSelection
from dam_recorder.taker import SerializedTaker
from dam_recorder.type_description import install_prefix_of, load_message_type
from dam_recorder.write_failure import WRITE_ERROR_STATUS, WriteFailure
from dam_recorder.writing import HURRIED_BACKLOG, BagWriting

#: Longest time [s] a stop request waits for messages still arriving (see begin_shutdown).
DRAIN_QUIET_S = 0.1
#: A stop that has taken longer than this when the bags are closed [s] leaves the node's
#: middleware entities to the end of the process (the process exits at once, with the bags
#: closed and the log flushed): a starved process takes seconds to delete them one by one.
TEARDOWN_SKIP_AFTER_S = 5.0
#: How often the taker thread takes what is queued [s].
TAKE_PERIOD_S = 0.005
#: How often the executor's thread writes what the taker took [s].
WRITE_PERIOD_S = 0.02
#: Topics found this long after the recorder started [s] were there when it began: DDS
#: discovery of the publishers already running takes a while (seconds on a loaded machine),
#: and what they sent before the start was never asked for. Later ones appeared while
#: recording (their messages before the subscription are counted).
STARTUP_DISCOVERY_S = 3.0
#: ... and the start-up window lasts at least this many discovery passes: on a loaded machine
#: the passes come late, and discovery, which runs on the same starved cores, is late too.
STARTUP_DISCOVERY_PASSES = 7


def _descriptor(description: str, **kwargs: Any) -> ParameterDescriptor:
    return ParameterDescriptor(description=description, read_only=True, **kwargs)


class RecorderNode(Node):
    """Subscribes to the selected topics as they appear and writes what arrives to a bag."""

    def __init__(self, overrides: dict[str, Any] | None = None) -> None:
        super().__init__('recorder', parameter_overrides=[
            Parameter(k, value=v) for k, v in (overrides or {}).items()])
        self._taker: SerializedTaker | None = None
        self._recorded: dict[str, RecordedTopic] = {}
        #: Selected topics seen in the graph without a publisher to subscribe to (yet).
        self._without_publisher: set[str] = set()
        #: Topics found in the first :data:`STARTUP_DISCOVERY_S`: the recording begins with
        #: them. A topic found later appeared while recording, and what it published before
        #: it was found is missing (counted by the writing's sequence numbers).
        self._found_first: set[str] = set()
        self._started_at = time.monotonic()
        self._discovery_passes = 0
        self._refused: dict[str, str] = {}  # topic -> why it is not recorded
        #: Episode mode: the goal events' bookkeeping.
        self._events: EpisodeEvents | None = None
        p = self._declare_parameters()
        self._selection = TopicSelection(p['topics'], p['regex'], p['exclude'])
        for topic in self._selection.topics:
            if self._selection.excluded(topic):
                self.get_logger().warning(f'{topic} is named but --exclude matches it: '
                                          'not recorded')
        if not p['episodes'] and (p['pre_roll'] != 3.0 or p['post_roll'] != 2.0):
            self.get_logger().warning('pre_roll and post_roll apply to episodes only '
                                      '(--episodes): ignored')
        output = p['output'] or time.strftime('rosbag2_%Y_%m_%d-%H_%M_%S')
        compression = p['compression'] or ('zstd' if p['storage'] == 'mcap' else 'none')
        #: The writing pipeline: the backlog, the bag or the episodes, the losses.
        self._writing = BagWriting(
            self._recorded, self.not_recorded, self.get_logger(), self._now_ns,
            max_backlog_bytes=int(p['max_backlog_bytes']),
            stop_write_s=float(p['stop_write_time']),
            use_sim_time=bool(self.get_parameter('use_sim_time').value),
            discovery_period_s=float(p['discovery_period']))
        writing = self._writing

        def open_bag(bag_dir: Path, file_stem: str | None,
                     custom_data: Any = writing.custom_data) -> BagWriter:
            return BagWriter(
                bag_dir, storage=p['storage'], compression=compression,
                max_file_bytes=p['max_bag_size'],
                max_file_duration_ns=int(round(p['max_bag_duration'] * 1e9)),
                ros_distro=os.environ.get('ROS_DISTRO', 'jazzy'), custom_data=custom_data,
                file_stem=file_stem)
        try:
            if p['episodes']:
                out_dir = Path(output).absolute()
                if out_dir.exists() and not out_dir.is_dir():
                    raise ConfigurationError(f'{out_dir} exists and is not a directory')
                writing.episodes = EpisodeRecorder(out_dir, open_bag, p['pre_roll'],
                                                   p['post_roll'], writing.custom_data)
                self._events = EpisodeEvents(writing.episodes, writing, self.get_logger(),
                                             self._now_ns, _read_episode_event)
                writing.on_taken_event = self._events.on_taken
            else:
                with SHUTDOWN.uninterrupted():  # a bag directory is made whole or not at all
                    writing.writer = open_bag(Path(output).absolute(), None)
            self._start(p, compression)
        except BaseException:  # a stop request or an error while starting: close the bag
            self.destroy_node()
            raise

    def _start(self, p: dict[str, Any], compression: str) -> None:
        self._depth = p['queue_depth']
        writing = self._writing
        self._taker = SerializedTaker(
            self, TAKE_PERIOD_S, on_swept=None if self._events is None else writing.swept)
        if writing.use_sim_time:  # first: every later message has the clock of its receipt
            receipts = writing.clock_receipts

            def on_clock(data: bytes, info: dict[str, Any]) -> None:
                clock_ns = clock_ns_of(data)
                if clock_ns is not None:
                    receipts.add(info.get('received_timestamp') or time.time_ns(), clock_ns)
            self._taker.subscribe(Clock, '/clock', QoSProfile(
                depth=1000, reliability=ReliabilityPolicy.BEST_EFFORT), on_clock, first=True)
        self.create_service(Trigger, '~/pause', self._on_pause, qos_profile=SERVICE_QOS)
        self.create_service(Trigger, '~/resume', self._on_resume, qos_profile=SERVICE_QOS)
        self.create_service(Trigger, '~/split', self._on_split, qos_profile=SERVICE_QOS)
        create_steady_timer(self, p['discovery_period'], self._discover)
        create_steady_timer(self, p['chunk_interval'], writing.flush)
        create_steady_timer(self, WRITE_PERIOD_S, writing.write_inbox)
        if self._events is not None:
            from dam_interfaces.msg import GraspEpisode  # episode mode needs the suite's types
            self.create_subscription(GraspEpisode, EPISODE_TOPIC, self._events.on_event,
                                     QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE,
                                                durability=DurabilityPolicy.VOLATILE))
            create_steady_timer(self, 0.05, self._events.close_due)
            target = (f'episodes into {self._events.episodes.out_dir} (pre-roll '
                      f'{p["pre_roll"]:g} s, post-roll {p["post_roll"]:g} s)')
        else:
            target = str(writing.writer.bag_dir)
        self.get_logger().info(
            f'recording {target} ({p["storage"]}, compression '
            f'{compression}): {", ".join(self._selection.topics) or "-"}'
            + (f', regex {p["regex"]!r}' if p['regex'] else '')
            + (f', exclude {p["exclude"]!r}' if p['exclude'] else ''))
        self._discover()

    def _declare_parameters(self) -> dict[str, Any]:
        declared = {
            'output': ('', _descriptor('bag directory to create; empty: rosbag2_<date>-<time>')),
            'storage': ('mcap', _descriptor('storage format: mcap or sqlite3')),
            'compression': ('', _descriptor('MCAP chunk compression zstd or none; empty: zstd '
                                             'for mcap, none for sqlite3')),
            'topics': (list(DEFAULT_TOPICS), _descriptor(
                'topics recorded by name', type=Parameter.Type.STRING_ARRAY.value)),
            'regex': ('', _descriptor('also record the topics this regular expression matches')),
            'exclude': ('', _descriptor('never record the topics this regular expression '
                                        'matches')),
            'max_bag_size': (0, _descriptor(
                f'no file larger than this once closed [bytes], at least {MIN_SPLIT_BYTES}; '
                '0: no limit',
                integer_range=[IntegerRange(from_value=0, to_value=2**62, step=1)])),
            'max_bag_duration': (0.0, _descriptor(
                'new file at this time span [s]; 0: no limit',
                floating_point_range=[FloatingPointRange(from_value=0.0, to_value=1e9)])),
            'chunk_interval': (1.0, _descriptor(
                'longest time a message waits in memory [s]: what a SIGKILL can lose',
                floating_point_range=[FloatingPointRange(
                    from_value=CHUNK_INTERVAL_RANGE_S[0], to_value=CHUNK_INTERVAL_RANGE_S[1])])),
            'discovery_period': (0.5, _descriptor(
                'how often new topics are looked for [s]',
                floating_point_range=[FloatingPointRange(from_value=0.01, to_value=60.0)])),
            'queue_depth': (5000, _descriptor(
                'depth of each subscription queue [messages]',
                integer_range=[IntegerRange(from_value=1, to_value=1_000_000, step=1)])),
            'max_backlog_bytes': (256 * 2**20, _descriptor(
                'most memory the messages waiting to be written may take [bytes]; beyond it '
                'messages are dropped and counted (never the goal events and statuses)',
                integer_range=[IntegerRange(from_value=10_000, to_value=2**40, step=1)])),
            'stop_write_time': (2.0, _descriptor(
                'after SIGINT or SIGTERM, how long the recorder goes on writing what it '
                'received before it counts the rest as not written and closes [s]',
                floating_point_range=[FloatingPointRange(from_value=0.0, to_value=60.0)])),
            'episodes': (False, _descriptor(
                'one bag per /dam_grasp goal, in the directory output')),
            'pre_roll': (3.0, _descriptor(
                'episode mode: seconds recorded before a goal starts [s]',
                floating_point_range=[FloatingPointRange(from_value=0.0, to_value=600.0)])),
            'post_roll': (2.0, _descriptor(
                'episode mode: seconds recorded after a goal ends [s]',
                floating_point_range=[FloatingPointRange(from_value=0.0, to_value=600.0)])),
        }
        return {name: self.declare_parameter(name, default, descriptor).value
                for name, (default, descriptor) in declared.items()}

    # -- topics ------------------------------------------------------------------------------

    def _discover(self) -> None:
        if self._writing.stopped or self.write_failure is not None or SHUTDOWN.requested:
            return
        if len(self._writing.inbox) > HURRIED_BACKLOG and self._discovery_passes > \
                STARTUP_DISCOVERY_PASSES:
            # Behind: the graph's queries wait for the middleware's threads, which a starved
            # process runs seldom; writing (and a stop request) come first.
            return
        for recorded in self._recorded.values():
            one = self.count_publishers(recorded.name) == 1
            if one and not recorded.one_publisher:
                recorded.last_sequence = None  # a new sequence to follow
            recorded.one_publisher = one
        topics = self.get_topic_names_and_types()
        self._discovery_passes += 1
        if time.monotonic() - self._started_at < STARTUP_DISCOVERY_S \
                or self._discovery_passes <= STARTUP_DISCOVERY_PASSES:
            self._found_first.update(name for name, _types in topics)
        for name, types in topics:
            if name in self._recorded or name in self._refused \
                    or not self._selection.selects(name):
                continue
            if len(types) != 1:
                self._refuse(name, f'published with {len(types)} types ({", ".join(types)})')
                continue
            offers = self.get_publishers_info_by_topic(name)
            if not offers:
                self._without_publisher.add(name)
                continue  # no publisher yet: its QoS decides the subscription's
            self._without_publisher.discard(name)
            try:
                self._record(name, types[0], offers)
            except BagWriteError as exc:
                self._writing.on_write_error(exc)
                return
            except DamRecorderError as exc:
                self._refuse(name, str(exc))
                continue
            self._recorded[name].appeared_late = name not in self._found_first

    def _refuse(self, name: str, reason: str) -> None:
        self._refused[name] = reason
        self.get_logger().warning(f'not recording {name}: {reason}')

    def _record(self, name: str, type_name: str, offers: Sequence[Any]) -> None:
        cls = message_class(type_name)
        package = type_name.split('/')[0]
        prefixes = [p for p in os.environ.get('AMENT_PREFIX_PATH', '').split(os.pathsep) if p]
        prefix = install_prefix_of(sys.modules[package].__file__ or '', package)
        message_type = load_message_type(type_name, prefixes + ([prefix] if prefix else []))
        end = CdrEnd(message_type)
        offered = [offered_qos(o) for o in offers]
        request = request_for_offers(name, offered, self._depth)
        for warning in request.warnings:
            self.get_logger().warning(warning)
        qos = QoSProfile(
            history=HistoryPolicy.KEEP_LAST, depth=request.depth,
            reliability=ReliabilityPolicy.RELIABLE if request.reliable
            else ReliabilityPolicy.BEST_EFFORT,
            durability=DurabilityPolicy.TRANSIENT_LOCAL if request.transient_local
            else DurabilityPolicy.VOLATILE)
        type_hash = message_type.type_hash or str(getattr(offers[0], 'topic_type_hash', ''))
        profiles = [to_rosbags_qos(o) for o in offered]
        writing = self._writing
        if writing.episodes is not None:
            topic_id = writing.episodes.add_topic(TopicSpec(
                name, type_name, message_type.definition(), type_hash, profiles,
                latched=request.transient_local, protected=name in PROTECTED_TOPICS))
        else:
            topic_id = writing.writer.add_topic(name, type_name, message_type.definition(),
                                                type_hash, profiles)
        recorded = RecordedTopic(name, topic_id, end, one_publisher=len(offers) == 1,
                             facts=self._fact_reader(name, type_name, cls),
                             protected=name in PROTECTED_TOPICS,
                             stamped=starts_with_header(cls))
        self._recorded[name] = recorded
        self._taker.subscribe(
            cls, name, qos, writing.intake(recorded),
            on_lost=lambda change, r=recorded: writing.lost_reported(r, change),
            on_incompatible=lambda change, policy, r=recorded: writing.on_incompatible(
                r, change, policy),
            first=recorded.protected)  # the goal's events: taken first, at a stop too
        self.get_logger().info(
            f'recording {name} ({type_name}, {"reliable" if request.reliable else "best_effort"}'
            f', {"transient_local" if request.transient_local else "volatile"})')

    def _fact_reader(self, name: str, type_name: str, cls: type) -> Any:
        """What an episode reads from the messages of ``name`` (None: nothing)."""
        if self._events is None:
            return None
        if name in COUNTED_TOPICS:
            def stamp(data: bytes) -> Facts:
                header = header_stamp_ns(data)
                return () if header is None else (('stamp', header),)
            return stamp
        if FACT_TYPES.get(name) != type_name:
            return None
        from rclpy.serialization import deserialize_message

        def read(data: bytes) -> Facts:
            msg = deserialize_message(data, cls)
            if name == DIAGNOSTICS_TOPIC:
                return diagnostic_counts((s.name, {kv.key: kv.value for kv in s.values})
                                         for s in msg.status)
            if name == EPISODE_TOPIC:
                return (('event', (msg.goal_id, int(msg.event))),)
            return [('status', (bytes(bytearray(s.goal_info.goal_id.uuid)).hex(),
                                int(s.status))) for s in msg.status_list]
        return read

    def not_recorded(self) -> dict[str, str]:
        """The selected topics the recording does not hold, each with the reason: named
        but never seen, seen without a publisher, or refused."""
        reasons = dict(self._refused)
        for name in self._without_publisher - set(self._recorded):
            reasons.setdefault(name, 'no publisher while recording (only subscribers)')
        for name in self._selection.topics:
            if name not in self._recorded and not self._selection.excluded(name):
                reasons.setdefault(name, 'never appeared while recording')
        return reasons

    @property
    def write_failure(self) -> WriteFailure | None:
        """The first write error of a bag (then the recorder stops, status 74)."""
        return self._writing.write_failure

    def _now_ns(self) -> int:
        return self.get_clock().now().nanoseconds

    # -- services ----------------------------------------------------------------------------

    def _on_pause(self, _request: Trigger.Request, response: Trigger.Response) -> Any:
        response.success = True
        response.message = 'was paused already' if self._writing.paused else 'paused'
        self._writing.paused = True
        self.get_logger().info(f'~/pause: {response.message}')
        return response

    def _on_resume(self, _request: Trigger.Request, response: Trigger.Response) -> Any:
        response.success = True
        response.message = 'resumed' if self._writing.paused else 'was recording already'
        self._writing.paused = False
        self.get_logger().info(f'~/resume: {response.message}')
        return response

    def _on_split(self, _request: Trigger.Request, response: Trigger.Response) -> Any:
        response = self._split(response)
        self.get_logger().info(f'~/split: {response.message}')
        return response

    def _split(self, response: Trigger.Response) -> Any:
        if self.write_failure is not None:
            response.success = False
            response.message = f'not recording: {self.write_failure.describe()}'
            return response
        try:
            return self._split_files(response)
        except BagWriteError as exc:
            self._writing.on_write_error(exc)
            response.success = False
            response.message = f'not recording: {exc}'
            return response

    def _split_files(self, response: Trigger.Response) -> Any:
        if self._events is not None:
            paths = self._events.episodes.split()
            response.success = True
            response.message = (f'now writing {", ".join(p.name for p in paths)}' if paths
                                else 'no episode is open: nothing to split')
            return response
        path = self._writing.writer.split()
        response.success = True
        response.message = f'now writing {path.name}'
        return response

    # -- shutdown ----------------------------------------------------------------------------

    def begin_shutdown(self) -> Future | None:
        """On a stop request: keep taking messages until none arrived for
        :data:`DRAIN_QUIET_S` (what was in flight is recorded), at most ``run_node``'s
        finishing time. From now on the backlog is written for ``stop_write_time`` at most
        (:meth:`destroy_node`)."""
        writing = self._writing
        backlog = writing.begin_stop()
        self.get_logger().info(
            f'stop requested: writing what was received ({counted(backlog, "message")} '
            f'waiting) for at most {writing.stop_write_s:g} s (stop_write_time), then closing')
        if writing.hurried:
            return None  # behind: nothing in flight is worth waiting for
        done = Future()

        def check() -> None:  # (behind: nothing is in flight that the backlog waits for)
            if not done.done() and (time.monotonic() - writing.last_message >= DRAIN_QUIET_S
                                    or time.monotonic() >= writing.stop_deadline
                                    or len(writing.inbox) > 1000):
                done.set_result(True)
        create_steady_timer(self, DRAIN_QUIET_S / 2, check)
        return done

    def destroy_node(self) -> None:
        """Take what reached the process, close the bag (summary, index and
        ``metadata.yaml``) or every open episode, then destroy the node."""
        writing = self._writing
        taker, self._taker = self._taker, None
        taken = time.time_ns()
        if taker is not None:
            taker.stop()
            taken = time.time_ns()
            if writing.stop_deadline is None:
                writing.stop_deadline = time.monotonic() + writing.stop_write_s
            for topic in taker.drain(writing.stop_deadline):
                recorded = self._recorded.get(topic)
                if recorded is not None:
                    recorded.not_taken = True
        writing.write_inbox(final=True)
        writing.taken_ns = taken
        writing.stopped = True
        if self._events is not None:
            self._events.close_all()
        writing.close_writer()
        asked = writing.stop_requested_at
        late = asked is not None and time.monotonic() - asked > TEARDOWN_SKIP_AFTER_S
        if writing.hurried or late:
            self.get_logger().warning(
                f'stop: the bags are closed {time.monotonic() - asked:.1f} s '
                'after the stop request; the recorder was behind: its subscriptions and '
                'services are left to the end of the process (deleting them one by one takes '
                'a starved process seconds)')
            return
        if taker is not None:
            taker.destroy()
        super().destroy_node()


def _read_episode_event(data: bytes) -> Any:
    """A ``/dam/episode`` message from its serialized data (raises on another type)."""
    from rclpy.serialization import deserialize_message

    from dam_interfaces.msg import GraspEpisode
    return deserialize_message(data, GraspEpisode)


def main(args: list[str] | None = None) -> None:
    """Run the recorder; exit with :data:`WRITE_ERROR_STATUS` after a write error."""
    argv = list(sys.argv if args is None else args)
    try:
        own = remove_ros_args(argv)[1:]
    except _rclpy.RCLError as exc:  # a malformed --ros-args part: one line, no traceback
        print(f'recorder: invalid ROS arguments: {" ".join(str(exc).split())}',
              file=sys.stderr)
        raise SystemExit(2) from None
    overrides = parameter_overrides(own)
    made: list[RecorderNode] = []

    def make() -> RecorderNode:
        made.append(RecorderNode(overrides))
        return made[-1]
    run_node(make, 'recorder', argv, startup_errors=(DamRecorderError,))
    status = WRITE_ERROR_STATUS if made and made[-1].write_failure is not None else 0
    # The bags are closed and rclpy (its log files too) is shut down: nothing is left to
    # finish. The interpreter's own teardown is skipped: a process starved of CPU time can
    # take seconds over it, and the stop is bounded (stop_write_time).
    sys.stdout.flush()
    sys.stderr.flush()
    os._exit(status)


if __name__ == '__main__':
    main()
