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

import json
import os
import sys
import time
from collections import deque
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
from dam_common.echo import brief_repr
from dam_common.node import run_node
from dam_common.service_qos import SERVICE_QOS
from dam_common.shutdown import SHUTDOWN
from dam_common.words import counted
from dam_recorder.backlog import BACKLOG_KEY, Backlog
from dam_recorder.bag_reading import (
    DROPPED_KEY,
    NOT_RECORDED_KEY,
    SHED_KEY,
    STOP_UNWRITTEN_KEY,
)
from dam_recorder.bag_writer import CHUNK_INTERVAL_RANGE_S, MIN_SPLIT_BYTES, BagWriter
from dam_recorder.cdr_end import CdrEnd
from dam_recorder.cli import parameter_overrides
from dam_recorder.clock_receipts import ClockReceipts, clock_ns_of
from dam_recorder.completeness import (
    COUNTED_TOPICS,
    DIAGNOSTICS_TOPIC,
    FACT_TYPES,
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
)
from dam_recorder.qos import request_for_offers, to_rosbags_qos
from dam_recorder.recorded_topics import (
    LOG_TIME_TEXT,
    PROTECTED_TOPICS,
    RecordedTopic,
    counts_json,
    header_log_time_ns,
    losses_text,
    lost_anything,
)
from dam_recorder.ros_types import message_class, offered_qos, starts_with_header
from dam_recorder.selection import DEFAULT_TOPICS, TopicSelection
from dam_recorder.taker import SerializedTaker
from dam_recorder.type_description import install_prefix_of, load_message_type
from dam_recorder.write_failure import WRITE_ERROR_STATUS, WriteFailure

#: Longest time [s] a stop request waits for messages still arriving (see begin_shutdown).
DRAIN_QUIET_S = 0.1
#: Longest time [s] one turn of the executor spends writing the backlog: the executor
#: comes back to its other work (a stop request, services, discovery) at least this often.
WRITE_SLICE_S = 0.05
#: After the stop's writing time, how long closing episodes may write the messages they held
#: back (:data:`~dam_recorder.episodes.HOLD_BACK_NS`) [s]; the rest is counted.
CLOSE_WRITE_S = 0.5
#: A stop that has taken longer than this when the bags are closed [s] leaves the node's
#: middleware entities to the end of the process (the process exits at once, with the bags
#: closed and the log flushed): a starved process takes seconds to delete them one by one.
TEARDOWN_SKIP_AFTER_S = 5.0
#: A stop with more messages than this waiting to be written is hurried: no wait for
#: messages in flight, and the subscriptions and services are not deleted one by one (each
#: deletion waits for the middleware's threads, which a starved process runs seldom).
HURRIED_BACKLOG = 1000
#: Memory a message in the backlog takes beside its data (the tuple and the middleware's
#: information dictionary) [bytes], for ``max_backlog_bytes``.
MESSAGE_OVERHEAD_BYTES = 400
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
        #: Messages of the protected topics and the middleware's loss reports: written before
        #: the inbox, never dropped.
        self._urgent: deque[tuple[Any, ...]] = deque()
        #: Bytes put into the inbox (the taker's thread) and taken out (the executor's).
        self._inbox_in_bytes = 0
        self._inbox_out_bytes = 0
        self._shed_total = 0  # (the taker's thread)
        self._shed_noted_total = 0
        #: The /clock receipts (use_sim_time): log times are receive times on that clock.
        self._clock_receipts = ClockReceipts()
        #: When the writing of the backlog ends after a stop request (time.monotonic()).
        self._stop_deadline: float | None = None
        self._stop_requested_at: float | None = None
        #: The stop came with a backlog (:data:`HURRIED_BACKLOG`): the middleware entities are
        #: left to the end of the process.
        self._hurried = False
        self._recorded: dict[str, RecordedTopic] = {}
        #: (goal id, event) of the goal events handled (each comes twice, see
        #: _on_episode_event).
        self._events_handled: set[tuple[str, int]] = set()
        #: Selected topics seen in the graph without a publisher to subscribe to (yet).
        self._without_publisher: set[str] = set()
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
        self._refused: dict[str, str] = {}  # topic -> why it is not recorded
        self._paused = False
        self._last_message = time.monotonic()
        self._backlog = Backlog()
        #: Every message received before this [ns] has been handed over (episode mode).
        self._taken_ns = 0
        p = self._declare_parameters()
        self._max_backlog_bytes = int(p['max_backlog_bytes'])
        self._stop_write_s = float(p['stop_write_time'])
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
        if self._use_sim_time:  # first: every later message has the clock of its receipt
            receipts = self._clock_receipts

            def on_clock(data: bytes, info: dict[str, Any]) -> None:
                clock_ns = clock_ns_of(data)
                if clock_ns is not None:
                    receipts.add(info.get('received_timestamp') or time.time_ns(), clock_ns)
            self._taker.subscribe(Clock, '/clock', QoSProfile(
                depth=1000, reliability=ReliabilityPolicy.BEST_EFFORT), on_clock, first=True)
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
        if self._stopped or self.write_failure is not None or SHUTDOWN.requested:
            return
        if len(self._inbox) > HURRIED_BACKLOG and self._discovery_passes > \
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
                self._on_write_error(exc)
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
        if self._episodes is not None:
            topic_id = self._episodes.add_topic(TopicSpec(
                name, type_name, message_type.definition(), type_hash, profiles,
                latched=request.transient_local, protected=name in PROTECTED_TOPICS))
        else:
            topic_id = self._writer.add_topic(name, type_name, message_type.definition(),
                                              type_hash, profiles)
        recorded = RecordedTopic(name, topic_id, end, one_publisher=len(offers) == 1,
                             facts=self._fact_reader(name, type_name, cls),
                             protected=name in PROTECTED_TOPICS,
                             stamped=starts_with_header(cls))
        self._recorded[name] = recorded
        self._taker.subscribe(
            cls, name, qos, self._callback(recorded),
            on_lost=lambda change, r=recorded: self._urgent.append(('lost', r, change)),
            on_incompatible=lambda change, policy, r=recorded: self._on_incompatible(
                r, change, policy),
            first=recorded.protected)  # the goal's events: taken first, at a stop too
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

    def _callback(self, recorded: RecordedTopic) -> Any:
        """What the taker's thread does with a message of ``recorded``: into the backlog
        (the urgent one for a protected topic), or dropped and counted when the backlog holds
        ``max_backlog_bytes`` already."""
        inbox = self._urgent if recorded.protected else self._inbox
        limit = self._max_backlog_bytes

        def on_message(data: bytes, info: dict[str, Any]) -> None:  # the taker's thread
            self._last_message = time.monotonic()
            size = len(data) + MESSAGE_OVERHEAD_BYTES
            if not recorded.protected:
                if self._inbox_in_bytes - self._inbox_out_bytes + size > limit:
                    recorded.shed += 1
                    self._shed_total += 1
                    return
                self._inbox_in_bytes += size
            recorded.queued += 1
            # (with the topic's count of dropped ones so far: the gap they leave in the
            # sequence numbers is the recorder's drop, not one on the way)
            inbox.append(('message', recorded, data, info, recorded.shed))
        return on_message

    def _write_inbox(self, final: bool = False) -> None:
        """Write what the taker took (in the executor's thread): the urgent messages first,
        then the backlog, for at most :data:`WRITE_SLICE_S` a turn (``final``: until the
        stop's deadline, then the rest is counted, :meth:`_give_up`).

        With ``use_sim_time``, messages that arrive before the first ``/clock`` are held (in
        order) and written once it comes, stamped with its time: a bag on simulated time never
        starts in 1970. When the recorder stops (``final``) without a ``/clock`` ever, they
        are written with their receive time (system clock)."""
        inbox = self._inbox
        if self._use_sim_time and not self._clock_started:
            if self._clock_receipts.started:
                self._clock_started = True
                held = self._waiting()
                self._before_clock = held
                self._to_release = held
                if held:
                    first = self._clock_receipts.at(0) or 0
                    self.get_logger().info(
                        f'{held} message(s) arrived before the first /clock: written now, '
                        f'stamped with its time ({first * 1e-9:.3f} s; counted in '
                        f'dam_recorder.before_clock_messages)')
            elif final:
                self._no_clock = True
                held = self._waiting()
                if held:
                    self.get_logger().warning(
                        f'no /clock came while recording (use_sim_time): {held} message(s) '
                        f'written with their receive time (system clock)')
            else:
                return  # held until the clock runs
        writer = self._writer if self._episodes is None else self._episodes
        urgent = self._urgent
        while urgent and not self._stopped:
            self._write_item(writer, urgent.popleft())
        if final and self._stop_deadline is None:
            self._stop_deadline = time.monotonic() + self._stop_write_s
        deadline = self._stop_deadline if final else time.monotonic() + WRITE_SLICE_S
        stop_request = SHUTDOWN if not final else None
        while inbox and not self._stopped:
            # Every message: a starved process may wait long for its next time slice.
            if time.monotonic() >= deadline or (stop_request is not None
                                                and stop_request.requested):
                break
            while urgent:  # (an event that came meanwhile goes first)
                self._write_item(writer, urgent.popleft())
            item = inbox.popleft()
            if item[0] == 'message':
                item[1].dequeued += 1
                self._inbox_out_bytes += len(item[2]) + MESSAGE_OVERHEAD_BYTES
            self._write_item(writer, item)
        if self._shed_total != self._shed_noted_total:
            self._note_shed()
        if final:
            while urgent and not self._stopped:
                self._write_item(writer, urgent.popleft())
            if inbox:
                self._give_up()

    def _waiting(self) -> int:
        """Messages taken and not yet written (both backlogs)."""
        return sum(r.queued - r.dequeued for r in self._recorded.values())

    def _write_item(self, writer: Any, item: tuple[Any, ...]) -> None:
        if item[0] == 'message':
            if item[1].protected:
                item[1].dequeued += 1
            self._releasing = self._to_release > 0
            self._to_release = max(self._to_release - 1, 0)
            try:
                self._write(writer, item[1], item[2], item[3], item[4])
            except BagWriteError as exc:
                self._on_write_error(exc)
        elif item[0] == 'swept':
            self._taken_ns = item[1]
        else:
            self._on_lost(item[1], item[2])

    def _note_shed(self) -> None:
        """Log what the taker dropped from the full backlog since the last look, and count it
        in the open episodes."""
        self._shed_noted_total = self._shed_total
        names = []
        for recorded in self._recorded.values():
            new = recorded.shed - recorded.shed_noted
            if new > 0:
                recorded.shed_noted += new
                names.append(f'{recorded.name} {recorded.shed}')
                if self._episodes is not None:
                    self._episodes.note_shed(recorded.topic_id, new)
        if names:
            self.get_logger().warning(
                f'the backlog is full (max_backlog_bytes {self._max_backlog_bytes}): messages '
                f'dropped and counted ({", ".join(names)} in all; never the goal events); the '
                f'recorder gets too little CPU time', throttle_duration_sec=5.0)

    def _give_up(self) -> None:
        """The stop's time ran out: count what is left in the backlog per topic as not
        written (dam_recorder.stop_unwritten_messages, and in the open episodes)."""
        self._inbox.clear()
        left = []
        for recorded in self._recorded.values():
            if recorded.protected:
                continue
            count = recorded.queued - recorded.dequeued
            if count <= 0:
                continue
            recorded.dequeued = recorded.queued
            recorded.unwritten_at_stop += count
            left.append(f'{recorded.name} {count}')
            if self._episodes is not None:
                self._episodes.note_unwritten_at_stop(recorded.topic_id, count)
        if left:
            self.get_logger().warning(
                f'stop: {self._stop_write_s:g} s of writing after the stop request did not '
                f'reach the end of the backlog: not written, counted ({", ".join(left)})')

    def _receipt_ns(self, received: int) -> int:
        """The receive time of a message received at ``received`` [ns, system clock]: that
        time, or with ``use_sim_time`` the simulated time at the receipt
        (:mod:`~dam_recorder.clock_receipts`)."""
        if self._use_sim_time and not self._no_clock:
            stamp = self._clock_receipts.at(received) if received else None
            return stamp if stamp is not None else self.get_clock().now().nanoseconds
        return received or time.time_ns()

    def _write(self, writer: Any, recorded: RecordedTopic, data: bytes,
               info: dict[str, Any], shed: int = 0) -> None:
        received = info.get('received_timestamp', 0)
        stamp = header_log_time_ns(recorded, data, self._receipt_ns(received))
        self._follow_sequence(recorded, info.get('publication_sequence_number'), stamp, shed)
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
            if recorded.name == EPISODE_TOPIC:
                self._on_taken_event(cut, stamp)
            writer.write(recorded.topic_id, stamp, cut, trimmed, self._read_facts(recorded, cut),
                         backlog)
        else:
            writer.write(recorded.topic_id, stamp, cut)

    def _read_facts(self, recorded: RecordedTopic, data: bytes) -> Facts | None:
        if recorded.facts is None:
            return None
        try:
            return recorded.facts(data)
        except Exception as exc:  # noqa: BLE001 - a message the recorder cannot read
            self.get_logger().warning(f'{recorded.name}: cannot read the message: '
                                      f'{brief_repr(exc)}',
                                      throttle_duration_sec=5.0)
            return None

    def _follow_sequence(self, recorded: RecordedTopic, sequence: int | None, stamp: int,
                         shed: int = 0) -> None:
        """Count the messages missing before this one by its publisher's sequence number
        (``shed``: the topic's count of messages the recorder dropped, up to this one; those
        are no gap on the way)."""
        if not sequence:
            return
        shed_between, recorded.last_shed = shed - recorded.last_shed, shed
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
        elif sequence > last + 1 + shed_between and recorded.one_publisher:
            gap = sequence - last - 1 - shed_between
            recorded.dropped += gap
            if self._episodes is not None:
                self._episodes.note_dropped(recorded.topic_id, gap, stamp)
            self.get_logger().warning(
                f'{recorded.name}: {gap} message(s) of its publisher never reached the recorder '
                f'(sequence {last} to {sequence}; {recorded.dropped} in all)',
                throttle_duration_sec=2.0)

    def _on_lost(self, recorded: RecordedTopic, change: int) -> None:
        recorded.lost += change
        if self._episodes is not None:
            self._episodes.note_lost(recorded.topic_id, change)
        self.get_logger().warning(f'{recorded.name}: the middleware reports {change} message(s) '
                                  f'lost ({recorded.lost} in all)')

    def _on_incompatible(self, recorded: RecordedTopic, change: int, policy: str) -> None:
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
            return counts_json(self._recorded.values(), attribute)
        return {'dam_recorder.lost_messages': counts('lost'),
                'dam_recorder.paused_messages': counts('paused'),
                'dam_recorder.trimmed_messages': counts('trimmed'),
                'dam_recorder.incompatible_publishers': counts('incompatible'),
                'dam_recorder.before_subscription_messages': counts('before_subscription'),
                'dam_recorder.before_clock_messages': str(self._before_clock),
                DROPPED_KEY: counts('dropped'), SHED_KEY: counts('shed'),
                STOP_UNWRITTEN_KEY: counts('unwritten_at_stop'),
                'dam_recorder.not_taken_topics': json.dumps(
                    sorted(r.name for r in self._recorded.values() if r.not_taken)),
                NOT_RECORDED_KEY: json.dumps(self.not_recorded(), sort_keys=True),
                'dam_recorder.logged_at_receipt_messages': counts('logged_at_receipt'),
                'dam_recorder.log_time': LOG_TIME_TEXT,
                BACKLOG_KEY: self._backlog.json()}

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

    def _on_episode_event(self, msg: Any, received_ns: int | None = None) -> None:
        """A goal event, from the subscription (received now) or taken with the recorded
        messages (at ``received_ns``, its log time), whichever comes first: a starved
        executor may take its subscription's late, while the event is in the bag."""
        if self._stopped or self.write_failure is not None:
            return
        key = (str(msg.goal_id), int(msg.event))
        if key in self._events_handled:
            return
        self._events_handled.add(key)
        now = self._now_ns() if received_ns is None else received_ns
        if msg.event == msg.EVENT_STARTED:
            try:
                path = self._episodes.started(msg.goal_id, now,
                                              stamp_ns(msg.header.stamp), start_info(msg))
            except BagWriteError as exc:
                self._on_write_error(exc)
                return
            self.get_logger().info(f'episode of goal {msg.goal_id[:8]}: recording into {path}')
        elif msg.event == msg.EVENT_ENDED:
            summary = summary_from_event(msg)
            if not self._episodes.ended(msg.goal_id, now, summary,
                                        ended_ns=summary['ended_ns']):
                self.get_logger().warning(
                    f'goal {msg.goal_id[:8]} ended ({msg.outcome_name}) but it started before '
                    'the recorder did: no episode')
        else:
            self.get_logger().warning(f'{EPISODE_TOPIC}: unknown event {msg.event}, ignored')

    def _on_taken_event(self, data: bytes, stamp: int) -> None:
        from rclpy.serialization import deserialize_message

        from dam_interfaces.msg import GraspEpisode
        try:
            msg = deserialize_message(data, GraspEpisode)
        except Exception:  # noqa: BLE001 - another type on the topic: the facts say so
            return
        self._on_episode_event(msg, stamp)

    def _taken_until_ns(self) -> int:
        """Every message received before this [ns] has been handed to the episodes (with
        use_sim_time: on the simulated clock, as the messages' log times)."""
        if self._use_sim_time and not self._no_clock:
            at = self._clock_receipts.at(self._taken_ns) if self._taken_ns else None
            return at or 0
        return self._taken_ns

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

    def begin_shutdown(self) -> Future | None:
        """On a stop request: keep taking messages until none arrived for
        :data:`DRAIN_QUIET_S` (what was in flight is recorded), at most ``run_node``'s
        finishing time. From now on the backlog is written for ``stop_write_time`` at most
        (:meth:`destroy_node`)."""
        self._stop_requested_at = time.monotonic()
        self._stop_deadline = self._stop_requested_at + self._stop_write_s
        backlog = self._waiting()
        self._hurried = backlog > HURRIED_BACKLOG
        self.get_logger().info(
            f'stop requested: writing what was received ({backlog} message(s) waiting) for '
            f'at most {self._stop_write_s:g} s (stop_write_time), then closing')
        if self._hurried:
            return None  # behind: nothing in flight is worth waiting for
        done = Future()

        def check() -> None:  # (behind: nothing is in flight that the backlog waits for)
            if not done.done() and (time.monotonic() - self._last_message >= DRAIN_QUIET_S
                                    or time.monotonic() >= self._stop_deadline
                                    or len(self._inbox) > 1000):
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
            if self._stop_deadline is None:
                self._stop_deadline = time.monotonic() + self._stop_write_s
            for topic in taker.drain(self._stop_deadline):
                recorded = self._recorded.get(topic)
                if recorded is not None:
                    recorded.not_taken = True
        self._write_inbox(final=True)
        self._taken_ns = taken
        self._stopped = True
        self._close_bags()
        late = self._stop_requested_at is not None and \
            time.monotonic() - self._stop_requested_at > TEARDOWN_SKIP_AFTER_S
        if self._hurried or late:
            self.get_logger().warning(
                f'stop: the bags are closed {time.monotonic() - self._stop_requested_at:.1f} s '
                'after the stop request; the recorder was behind: its subscriptions and '
                'services are left to the end of the process (deleting them one by one takes '
                'a starved process seconds)')
            return
        if taker is not None:
            taker.destroy()
        super().destroy_node()

    def _close_bags(self) -> None:
        if self._episodes is not None:
            before = len(self._episodes.finished)
            try:
                self._episodes.close_all(self._taken_until_ns(), self._close_deadline())
            except BagWriteError as exc:  # (close_all closes every episode all the same)
                self._on_write_error(exc)
            for name, count in self._episodes.held_unwritten.items():
                if name in self._recorded:
                    self._recorded[name].unwritten_at_stop += count
            for closed in self._episodes.finished[before:]:
                self._log_episode(closed)
            incomplete = sum(1 for c in self._episodes.finished if c.missing)
            unwritten = self._episodes.unwritten_count()
            text = (f'{len(self._episodes.finished)} episode(s) recorded in '
                    f'{self._episodes.out_dir} ({incomplete} incomplete); '
                    f'{self._losses(unwritten)}')
            log = self.get_logger().warning if incomplete or unwritten or \
                self._lost() else self.get_logger().info
            log(text)
        writer, self._writer = self._writer, None
        if writer is None:
            return
        try:
            writer.close()
        except BagWriteError as exc:
            self._on_write_error(exc)
        count = sum(t.message_count for t in writer.topics)
        unwritten = sum(writer.unwritten.values())
        text = (f'closed {writer.bag_dir}: {counted(count, "message")} on '
                f'{counted(len(writer.topics), "topic")} in '
                f'{counted(len(writer.files), "file")}; {self._losses(unwritten)}')
        if writer.failure is None:
            (self.get_logger().warning if self._lost() else self.get_logger().info)(
                text)
            return
        where = 'metadata.yaml says so' if writer.metadata_current else (
            'metadata.yaml could not be written: run recover on the bag')
        self.get_logger().warning(f'{text} ({writer.failure.errno_name}; {where})')

    def _losses(self, unwritten: int) -> str:
        return losses_text(self._recorded.values(), unwritten, self._backlog.describe(),
                           self.not_recorded())

    def _lost(self) -> bool:
        return lost_anything(self._recorded.values(), self.not_recorded())

    def _close_deadline(self) -> float | None:
        """Until when closing episodes write what they held back (None: no limit)."""
        if self._stop_deadline is None:
            return None
        if self._hurried:
            return time.monotonic()  # what was held back is counted, not written
        return self._stop_deadline + CLOSE_WRITE_S



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
