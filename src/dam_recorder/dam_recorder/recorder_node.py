"""``recorder``: records topics into a rosbag2 bag (the thin ROS layer over the core).

Run it with ``ros2 run dam_recorder recorder -o DIR [topics...]`` (``--help`` lists the
options; each is also a parameter below).

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
episodes : bool
    Episode mode: one bag per ``/dam_grasp`` goal in the directory ``output``
    (:mod:`~dam_recorder.episodes`), from ``pre_roll`` before the goal to ``post_roll`` after.
pre_roll, post_roll : double [s]
    What an episode holds before its goal starts and after it ends.

Messages are taken serialized (``raw=True``: never deserialized), cut at their CDR end
(:mod:`~dam_recorder.cdr_end`) and stamped with the time the middleware received them (the
node's clock with ``use_sim_time:=true``). Services (``std_srvs/srv/Trigger``): ``~/pause``,
``~/resume``, ``~/split``. SIGINT and SIGTERM close the bag (``destroy_node``).

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

import importlib
import json
import os
import sys
import time
from collections import deque
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor
from rclpy.impl.implementation_singleton import rclpy_implementation as _rclpy
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from rclpy.task import Future
from rclpy.utilities import remove_ros_args
from std_srvs.srv import Trigger

from dam_common.clock import create_steady_timer
from dam_common.echo import brief_repr
from dam_common.node import run_node
from dam_common.service_qos import SERVICE_QOS
from dam_common.shutdown import SHUTDOWN
from dam_recorder.backlog import BACKLOG_KEY, Backlog
from dam_recorder.bag_reading import DROPPED_KEY
from dam_recorder.bag_writer import CHUNK_INTERVAL_RANGE_S, MIN_SPLIT_BYTES, BagWriter
from dam_recorder.cdr_end import CdrEnd
from dam_recorder.cli import parameter_overrides
from dam_recorder.completeness import (
    ACTION_STATUS_TOPIC,
    COUNTED_TOPICS,
    DIAGNOSTICS_TOPIC,
    Facts,
    describe,
    diagnostic_counts,
    header_stamp_ns,
)
from dam_recorder.episode_messages import (
    EPISODE_TOPIC,
    stamp_ns,
    start_info,
    summary_from_event,
)
from dam_recorder.episodes import EpisodeRecorder, TopicSpec
from dam_recorder.errors import (
    BagWriteError,
    CdrError,
    ConfigurationError,
    DamRecorderError,
    TypeDescriptionError,
)
from dam_recorder.qos import OfferedQos, request_for_offers, to_rosbags_qos
from dam_recorder.selection import DEFAULT_TOPICS, TopicSelection
from dam_recorder.taker import SerializedTaker
from dam_recorder.type_description import install_prefix_of, load_message_type
from dam_recorder.write_failure import WRITE_ERROR_STATUS, WriteFailure

#: Longest time [s] a stop request waits for messages still arriving (see begin_shutdown).
DRAIN_QUIET_S = 0.1
#: How often the taker thread takes what is queued [s].
TAKE_PERIOD_S = 0.005
#: How often the executor's thread writes what the taker took [s].
WRITE_PERIOD_S = 0.02
#: Bytes after a message's CDR end that are its final alignment (kept; more is cut).
MAX_ALIGNMENT_PADDING = 3
#: A message handed to the bag longer than this after its receipt is logged (throttled) [ns].
BACKLOG_WARNING_NS = 1_000_000_000
#: Topics found this long after the recorder started [s] were there when it began: DDS
#: discovery of the publishers already running takes a while (seconds on a loaded machine),
#: and what they sent before the start was never asked for. Later ones appeared while
#: recording (their messages before the subscription are counted).
STARTUP_DISCOVERY_S = 3.0
#: ... and the start-up window lasts at least this many discovery passes: on a loaded machine
#: the passes come late, and discovery, which runs on the same starved cores, is late too.
STARTUP_DISCOVERY_PASSES = 7
#: The types whose messages an episode reads facts from (:mod:`dam_recorder.completeness`).
FACT_TYPES = {DIAGNOSTICS_TOPIC: 'diagnostic_msgs/msg/DiagnosticArray',
              EPISODE_TOPIC: 'dam_interfaces/msg/GraspEpisode',
              ACTION_STATUS_TOPIC: 'action_msgs/msg/GoalStatusArray'}


def message_class(type_name: str) -> type:
    """The Python class of ``type_name`` (``pkg/msg/Name``, or a type derived from an action
    or a service such as ``pkg/action/Name_FeedbackMessage``).

    Raises
    ------
    TypeDescriptionError
        If the class cannot be imported (the message names the type).
    """
    try:
        package, kind, name = type_name.split('/')
        module = importlib.import_module(f'{package}.{kind}')
    except (ValueError, ImportError) as exc:
        raise TypeDescriptionError(f'cannot import the type {type_name!r}: {exc}') from None
    if hasattr(module, name):
        return getattr(module, name)
    for cut in range(len(name) - 1, 0, -1):  # Name_FeedbackMessage lives beside Name
        base = getattr(module, name[:cut], None) if name[cut] == '_' else None
        derived = getattr(sys.modules.get(getattr(base, '__module__', '')), name, None)
        if derived is not None:
            return derived
    raise TypeDescriptionError(f'cannot import the type {type_name!r}: no class {name}')


def offered_qos(info: Any) -> OfferedQos:
    """The :class:`OfferedQos` of an rclpy ``TopicEndpointInfo``."""
    qos = info.qos_profile
    return OfferedQos(
        history=qos.history.name, depth=int(qos.depth), reliability=qos.reliability.name,
        durability=qos.durability.name, deadline_ns=qos.deadline.nanoseconds,
        lifespan_ns=qos.lifespan.nanoseconds, liveliness=qos.liveliness.name,
        liveliness_lease_duration_ns=qos.liveliness_lease_duration.nanoseconds,
        avoid_ros_namespace_conventions=bool(qos.avoid_ros_namespace_conventions))


@dataclass
class _Recorded:
    """A topic being recorded."""

    name: str
    topic_id: int
    end: CdrEnd
    lost: int = 0
    paused: int = 0
    trimmed: int = 0
    malformed: int = 0
    dropped: int = 0
    #: Publishers that joined with a QoS the subscription cannot match (nothing of theirs is
    #: recorded).
    incompatible: int = 0
    #: The topic appeared after the recording began (found by a later discovery).
    appeared_late: bool = False
    #: Messages its publisher sent before the recorder had subscribed (a late topic).
    before_subscription: int = 0
    #: Gaps in the publication sequence numbers count as dropped while the topic has one
    #: publisher (rclpy does not say which publisher sent a message).
    one_publisher: bool = False
    last_sequence: int | None = None
    #: A sequence number of the topic was seen.
    followed: bool = False
    #: What an episode reads from a message (None: nothing).
    facts: Any = None


def _descriptor(description: str, **kwargs: Any) -> ParameterDescriptor:
    return ParameterDescriptor(description=description, read_only=True, **kwargs)


class RecorderNode(Node):
    """Subscribes to the selected topics as they appear and writes what arrives to a bag."""

    def __init__(self, overrides: dict[str, Any] | None = None) -> None:
        super().__init__('recorder', parameter_overrides=[
            Parameter(k, value=v) for k, v in (overrides or {}).items()])
        self._writer: BagWriter | None = None
        self._episodes: EpisodeRecorder | None = None
        self._stopped = False
        #: The first write error of a bag (then the recorder stops, status 74).
        self.write_failure: WriteFailure | None = None
        self._taker: SerializedTaker | None = None
        #: What the taker's thread took, for the executor's thread to write: ('message',
        #: recorded, data, info) or ('lost', recorded, count). Only the executor's thread
        #: touches the writer (sqlite3 connections belong to the thread that opened them).
        self._inbox: deque[tuple[Any, ...]] = deque()
        self._recorded: dict[str, _Recorded] = {}
        #: use_sim_time: the first /clock has come (until then messages are held), or never
        #: came while recording (then they are stamped with their receive time).
        self._clock_started = False
        self._no_clock = False
        self._before_clock = 0
        self._releasing = False  # writing the messages held for the first /clock
        self._to_release = 0  # of those, how many are still to be written
        #: Topics found in the first :data:`STARTUP_DISCOVERY_S`: the recording begins with
        #: them. A topic found later appeared while recording, and what it published before
        #: it was found is missing (counted: :meth:`_follow_sequence`).
        self._found_first: set[str] = set()
        self._started_at = time.monotonic()
        self._discovery_passes = 0
        self._refused: set[str] = set()
        self._paused = False
        self._last_message = time.monotonic()
        self._backlog = Backlog()
        #: Every message received before this [ns] has been handed over (episode mode).
        self._taken_ns = 0
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
        self._use_sim_time = bool(self.get_parameter('use_sim_time').value)

        def open_bag(bag_dir: Path, file_stem: str | None,
                     custom_data: Any = self._custom_data) -> BagWriter:
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
                self._episodes = EpisodeRecorder(out_dir, open_bag, p['pre_roll'],
                                                 p['post_roll'], self._custom_data)
            else:
                with SHUTDOWN.uninterrupted():  # a bag directory is made whole or not at all
                    self._writer = open_bag(Path(output).absolute(), None)
            self._start(p, compression)
        except BaseException:  # a stop request or an error while starting: close the bag
            self.destroy_node()
            raise

    def _start(self, p: dict[str, Any], compression: str) -> None:
        self._depth = p['queue_depth']
        inbox = self._inbox
        self._taker = SerializedTaker(
            self, TAKE_PERIOD_S,
            on_swept=None if self._episodes is None else lambda t: inbox.append(('swept', t)))
        self.create_service(Trigger, '~/pause', self._on_pause, qos_profile=SERVICE_QOS)
        self.create_service(Trigger, '~/resume', self._on_resume, qos_profile=SERVICE_QOS)
        self.create_service(Trigger, '~/split', self._on_split, qos_profile=SERVICE_QOS)
        self._discovery_period = float(p['discovery_period'])
        create_steady_timer(self, p['discovery_period'], self._discover)
        create_steady_timer(self, p['chunk_interval'], self._flush)
        create_steady_timer(self, WRITE_PERIOD_S, self._write_inbox)
        if self._episodes is not None:
            from dam_interfaces.msg import GraspEpisode  # episode mode needs the suite's types
            self.create_subscription(GraspEpisode, EPISODE_TOPIC, self._on_episode_event,
                                     QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE,
                                                durability=DurabilityPolicy.VOLATILE))
            create_steady_timer(self, 0.05, self._close_due_episodes)
            target = (f'episodes into {self._episodes.out_dir} (pre-roll {p["pre_roll"]:g} s, '
                      f'post-roll {p["post_roll"]:g} s)')
        else:
            target = str(self._writer.bag_dir)
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
        if self._stopped or self.write_failure is not None:
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
                continue  # no publisher yet: its QoS decides the subscription's
            try:
                self._record(name, types[0], offers)
            except BagWriteError as exc:
                self._on_write_error(exc)
                return
            except DamRecorderError as exc:
                self._refuse(name, str(exc))
                continue
            self._recorded[name].appeared_late = name not in self._found_first

    def _refuse(self, name: str, reason: str) -> None:
        self._refused.add(name)
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
        if self._episodes is not None:
            topic_id = self._episodes.add_topic(TopicSpec(
                name, type_name, message_type.definition(), type_hash, profiles,
                latched=request.transient_local))
        else:
            topic_id = self._writer.add_topic(name, type_name, message_type.definition(),
                                              type_hash, profiles)
        recorded = _Recorded(name, topic_id, end, one_publisher=len(offers) == 1,
                             facts=self._fact_reader(name, type_name, cls))
        self._recorded[name] = recorded
        self._taker.subscribe(
            cls, name, qos, self._callback(recorded),
            on_lost=lambda change, r=recorded: self._inbox.append(('lost', r, change)),
            on_incompatible=lambda change, policy, r=recorded: self._on_incompatible(
                r, change, policy))
        self.get_logger().info(
            f'recording {name} ({type_name}, {"reliable" if request.reliable else "best_effort"}'
            f', {"transient_local" if request.transient_local else "volatile"})')

    def _fact_reader(self, name: str, type_name: str, cls: type) -> Any:
        """What an episode reads from the messages of ``name`` (None: nothing)."""
        if self._episodes is None:
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

    def _callback(self, recorded: _Recorded) -> Any:
        inbox = self._inbox

        def on_message(data: bytes, info: dict[str, Any]) -> None:  # the taker's thread
            self._last_message = time.monotonic()
            inbox.append(('message', recorded, data, info))
        return on_message

    def _write_inbox(self, final: bool = False) -> None:
        """Write what the taker took (in the executor's thread).

        With ``use_sim_time``, messages that arrive before the first ``/clock`` are held (in
        order) and written once it comes, stamped with the clock's time then: a bag on
        simulated time never starts in 1970. When the recorder stops (``final``) without a
        ``/clock`` ever, they are written with their receive time (system clock)."""
        inbox = self._inbox
        if self._use_sim_time and not self._clock_started:
            held = sum(1 for item in inbox if item[0] == 'message')
            if self.get_clock().now().nanoseconds > 0:
                self._clock_started = True
                self._before_clock = held
                self._to_release = held
                if held:
                    self.get_logger().info(
                        f'{held} message(s) arrived before the first /clock: written now, '
                        f'stamped with its time ({self.get_clock().now().nanoseconds * 1e-9:.3f}'
                        f' s; counted in dam_recorder.before_clock_messages)')
            elif final:
                self._no_clock = True
                if held:
                    self.get_logger().warning(
                        f'no /clock came while recording (use_sim_time): {held} message(s) '
                        f'written with their receive time (system clock)')
            else:
                return  # held until the clock runs
        writer = self._writer if self._episodes is None else self._episodes
        while inbox and not self._stopped:
            item = inbox.popleft()
            if item[0] == 'message':
                self._releasing = self._to_release > 0
                self._to_release = max(self._to_release - 1, 0)
                try:
                    self._write(writer, item[1], item[2], item[3])
                except BagWriteError as exc:
                    self._on_write_error(exc)
            elif item[0] == 'swept':
                self._taken_ns = item[1]
            else:
                self._on_lost(item[1], item[2])

    def _write(self, writer: Any, recorded: _Recorded, data: bytes,
               info: dict[str, Any]) -> None:
        received = info.get('received_timestamp', 0)
        stamp = received
        if (self._use_sim_time and not self._no_clock) or not stamp:
            stamp = self.get_clock().now().nanoseconds
        self._follow_sequence(recorded, info.get('publication_sequence_number'), stamp)
        if self._paused:
            recorded.paused += 1
            if self._episodes is not None:
                self._episodes.note_paused(recorded.topic_id)
            return
        # (Messages held for the first /clock waited for it, not for CPU time.)
        backlog = time.time_ns() - received if received and not self._releasing else None
        if backlog is not None:
            self._backlog.add(backlog)
            if backlog > BACKLOG_WARNING_NS:
                self.get_logger().warning(
                    f'writing {backlog * 1e-9:.2f} s behind the receipt of the messages '
                    f'({recorded.name}): the recorder gets too little CPU time',
                    throttle_duration_sec=5.0)
        try:
            cut = recorded.end.trim(data)
            if len(data) - len(cut) <= MAX_ALIGNMENT_PADDING:
                cut = data  # the final alignment: part of a CDR message, kept as received
        except CdrError as exc:
            if not recorded.malformed:
                self.get_logger().warning(f'{recorded.name}: {exc}; written as received')
            recorded.malformed += 1
            cut = data
        trimmed = len(cut) != len(data)
        recorded.trimmed += trimmed
        if self._episodes is not None:
            writer.write(recorded.topic_id, stamp, cut, trimmed, self._read_facts(recorded, cut),
                         backlog)
        else:
            writer.write(recorded.topic_id, stamp, cut)

    def _read_facts(self, recorded: _Recorded, data: bytes) -> Facts | None:
        if recorded.facts is None:
            return None
        try:
            return recorded.facts(data)
        except Exception as exc:  # noqa: BLE001 - a message the recorder cannot read
            self.get_logger().warning(f'{recorded.name}: cannot read the message: '
                                      f'{brief_repr(exc)}',
                                      throttle_duration_sec=5.0)
            return None

    def _follow_sequence(self, recorded: _Recorded, sequence: int | None, stamp: int) -> None:
        """Count the messages missing before this one by its publisher's sequence number."""
        if not sequence:
            return
        last, recorded.last_sequence = recorded.last_sequence, sequence
        first, recorded.followed = not recorded.followed, True
        if last is None:
            # Only the topic's first message tells what came before the subscription: a
            # sequence followed anew (a second publisher came and went) does not.
            if first and recorded.appeared_late and recorded.one_publisher and sequence > 1:
                # Published before the topic was found and subscribed to: a volatile topic
                # keeps nothing for a late subscriber.
                recorded.before_subscription = sequence - 1
                self.get_logger().warning(
                    f'{recorded.name} appeared while recording: its publisher sent '
                    f'{sequence - 1} message(s) before the recorder had found and subscribed '
                    f'to it (discovery_period {self._discovery_period:g} s); they are not in '
                    f'the bag (counted in its custom data '
                    f'dam_recorder.before_subscription_messages)')
            return
        if sequence <= last:  # another publisher's: gaps mean nothing until the graph says one
            recorded.one_publisher = False
        elif sequence > last + 1 and recorded.one_publisher:
            gap = sequence - last - 1
            recorded.dropped += gap
            if self._episodes is not None:
                self._episodes.note_dropped(recorded.topic_id, gap, stamp)
            self.get_logger().warning(
                f'{recorded.name}: {gap} message(s) of its publisher never reached the recorder '
                f'(sequence {last} to {sequence}; {recorded.dropped} in all)',
                throttle_duration_sec=2.0)

    def _on_lost(self, recorded: _Recorded, change: int) -> None:
        recorded.lost += change
        if self._episodes is not None:
            self._episodes.note_lost(recorded.topic_id, change)
        self.get_logger().warning(f'{recorded.name}: the middleware reports {change} message(s) '
                                  f'lost ({recorded.lost} in all)')

    def _on_incompatible(self, recorded: _Recorded, change: int, policy: str) -> None:
        """The taker's thread: ``change`` more publishers of the topic offer a QoS its
        subscription cannot match. Logged once per topic, counted in the bag's custom data
        (``dam_recorder.incompatible_publishers``)."""
        first = recorded.incompatible == 0
        recorded.incompatible += change
        if first:
            self.get_logger().warning(
                f'{recorded.name}: a publisher joined offering a QoS this recording cannot '
                f'take ({policy}; the topic is recorded as its first publishers offered it): '
                f'none of its messages are recorded (counted in the bag\'s custom data '
                f'dam_recorder.incompatible_publishers; logged once per topic)')

    def _custom_data(self) -> dict[str, str]:
        def counts(attribute: str) -> str:
            return json.dumps({r.name: getattr(r, attribute) for r in self._recorded.values()
                               if getattr(r, attribute)}, sort_keys=True)
        return {'dam_recorder.lost_messages': counts('lost'),
                'dam_recorder.paused_messages': counts('paused'),
                'dam_recorder.trimmed_messages': counts('trimmed'),
                'dam_recorder.incompatible_publishers': counts('incompatible'),
                'dam_recorder.before_subscription_messages': counts('before_subscription'),
                'dam_recorder.before_clock_messages': str(self._before_clock),
                DROPPED_KEY: counts('dropped'), BACKLOG_KEY: self._backlog.json()}

    # -- services and timers -----------------------------------------------------------------

    def _flush(self) -> None:
        try:
            if self._writer is not None and not self._writer.closed:
                self._writer.flush()
            if self._episodes is not None and not self._stopped:
                self._episodes.flush()
        except BagWriteError as exc:
            self._on_write_error(exc)

    def _on_write_error(self, exc: BagWriteError) -> None:
        """The first write error: log it once, stop (the executor ends the node, which closes
        what is open, and ``main`` exits with :data:`WRITE_ERROR_STATUS`). Later ones (other
        episode bags on the same file system) are counted by their bags, not logged."""
        if self.write_failure is not None:
            return
        self.write_failure = exc.failure
        self.get_logger().error(
            f'{exc}: recording stopped; the bag is closed with the messages on disk, every '
            f'message not written is counted (dam_recorder.unwritten_messages); the recorder '
            f'exits with status {WRITE_ERROR_STATUS}')
        SHUTDOWN.request()

    def _now_ns(self) -> int:
        return self.get_clock().now().nanoseconds

    def _on_episode_event(self, msg: Any) -> None:
        if self._stopped or self.write_failure is not None:
            return
        if msg.event == msg.EVENT_STARTED:
            try:
                path = self._episodes.started(msg.goal_id, self._now_ns(),
                                              stamp_ns(msg.header.stamp), start_info(msg))
            except BagWriteError as exc:
                self._on_write_error(exc)
                return
            self.get_logger().info(f'episode of goal {msg.goal_id[:8]}: recording into {path}')
        elif msg.event == msg.EVENT_ENDED:
            summary = summary_from_event(msg)
            if not self._episodes.ended(msg.goal_id, self._now_ns(), summary,
                                        ended_ns=summary['ended_ns']):
                self.get_logger().warning(
                    f'goal {msg.goal_id[:8]} ended ({msg.outcome_name}) but it started before '
                    'the recorder did: no episode')
        else:
            self.get_logger().warning(f'{EPISODE_TOPIC}: unknown event {msg.event}, ignored')

    def _taken_until_ns(self) -> int:
        """Every message received before this [ns] has been handed to the episodes (with
        use_sim_time the node's clock stamps each message as it is handed over)."""
        return self._now_ns() if self._use_sim_time else self._taken_ns

    def _close_due_episodes(self) -> None:
        if self._stopped or self.write_failure is not None:
            return  # (after a write error the episodes are closed as the node ends)
        try:
            for closed in self._episodes.poll(self._taken_until_ns()):
                self._log_episode(closed)
        except BagWriteError as exc:
            self._on_write_error(exc)

    def _log_episode(self, closed: Any) -> None:
        # 'episode OUTCOME: PATH' alone on its line: scripts read the path from it.
        if closed.missing:
            self.get_logger().warning(f'episode {closed.outcome}: {closed.path}')
            self.get_logger().warning(f'{closed.path.name} is INCOMPLETE, the bag lacks: '
                                      + '; '.join(describe(closed.missing)))
        else:
            self.get_logger().info(f'episode {closed.outcome}: {closed.path}')

    def _on_pause(self, _request: Trigger.Request, response: Trigger.Response) -> Any:
        response.success = True
        response.message = 'was paused already' if self._paused else 'paused'
        self._paused = True
        self.get_logger().info(f'~/pause: {response.message}')
        return response

    def _on_resume(self, _request: Trigger.Request, response: Trigger.Response) -> Any:
        response.success = True
        response.message = 'resumed' if self._paused else 'was recording already'
        self._paused = False
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
            self._on_write_error(exc)
            response.success = False
            response.message = f'not recording: {exc}'
            return response

    def _split_files(self, response: Trigger.Response) -> Any:
        if self._episodes is not None:
            paths = self._episodes.split()
            response.success = True
            response.message = (f'now writing {", ".join(p.name for p in paths)}' if paths
                                else 'no episode is open: nothing to split')
            return response
        path = self._writer.split()
        response.success = True
        response.message = f'now writing {path.name}'
        return response

    # -- shutdown ----------------------------------------------------------------------------

    def begin_shutdown(self) -> Future:
        """On a stop request: keep taking messages until none arrived for
        :data:`DRAIN_QUIET_S` (what was in flight is recorded), at most ``run_node``'s
        finishing time."""
        done = Future()

        def check() -> None:
            if not done.done() and time.monotonic() - self._last_message >= DRAIN_QUIET_S:
                done.set_result(True)
        create_steady_timer(self, DRAIN_QUIET_S / 2, check)
        return done

    def destroy_node(self) -> None:
        """Take what reached the process, close the bag (summary, index and
        ``metadata.yaml``) or every open episode, then destroy the node."""
        taker, self._taker = self._taker, None
        taken = time.time_ns()
        if taker is not None:
            taker.stop()
            taken = time.time_ns()
            taker.drain()
        self._write_inbox(final=True)
        self._taken_ns = taken
        self._stopped = True
        self._close_bags()
        if taker is not None:
            taker.destroy()
        super().destroy_node()

    def _close_bags(self) -> None:
        if self._episodes is not None:
            before = len(self._episodes.finished)
            try:
                self._episodes.close_all(self._taken_until_ns())
            except BagWriteError as exc:  # (close_all closes every episode all the same)
                self._on_write_error(exc)
            for closed in self._episodes.finished[before:]:
                self._log_episode(closed)
            incomplete = sum(1 for c in self._episodes.finished if c.missing)
            unwritten = self._episodes.unwritten_count()
            log = self.get_logger().warning if unwritten else self.get_logger().info
            log(f'{len(self._episodes.finished)} episode(s) recorded in '
                f'{self._episodes.out_dir} ({incomplete} incomplete); not written '
                f'{unwritten}; backlog {self._backlog.describe()}; dropped '
                f'{self._dropped_text()}')
        writer, self._writer = self._writer, None
        if writer is None:
            return
        try:
            writer.close()
        except BagWriteError as exc:
            self._on_write_error(exc)
        count = sum(t.message_count for t in writer.topics)
        lost = sum(r.lost for r in self._recorded.values())
        unwritten = sum(writer.unwritten.values())
        text = (f'closed {writer.bag_dir}: {count} messages on {len(writer.topics)} topics in '
                f'{len(writer.files)} file(s); not written {unwritten}; the middleware reported '
                f'{lost} lost; dropped {self._dropped_text()}; backlog '
                f'{self._backlog.describe()}')
        if writer.failure is None:
            self.get_logger().info(text)
            return
        where = 'metadata.yaml says so' if writer.metadata_current else (
            'metadata.yaml could not be written: run recover on the bag')
        self.get_logger().warning(f'{text} ({writer.failure.errno_name}; {where})')

    def _dropped_text(self) -> str:
        dropped = {r.name: r.dropped for r in self._recorded.values() if r.dropped}
        return ', '.join(f'{n} {c}' for n, c in sorted(dropped.items())) or "none"


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
    if made and made[-1].write_failure is not None:
        raise SystemExit(WRITE_ERROR_STATUS)


if __name__ == '__main__':
    main()
