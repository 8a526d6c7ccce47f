"""Receive times on the simulated clock: the value of the last /clock received at or before a
message's receipt, whatever the order in which the two threads add and read."""

from __future__ import annotations

import struct
import threading

import pytest

from dam_recorder.clock_receipts import ClockReceipts, clock_ns_of

MS = 1_000_000


def test_a_receipt_maps_to_the_clock_received_last_before_it() -> None:
    receipts = ClockReceipts()
    assert not receipts.started and receipts.at(5 * MS) is None
    for i in range(10):  # /clock i*10 ms (simulated) received at 1000 + i*20 ms (system)
        receipts.add((1000 + 20 * i) * MS, 10 * i * MS)
    assert receipts.started
    assert receipts.at(1000 * MS) == 0  # received with the first tick
    assert receipts.at(1019 * MS) == 0
    assert receipts.at(1020 * MS) == 10 * MS
    assert receipts.at(1185 * MS) == 90 * MS  # after the last: the last value
    assert receipts.at(500 * MS) == 0  # before every receipt: the first value


def test_a_clock_that_starts_over_is_followed_and_counted() -> None:
    receipts = ClockReceipts()
    receipts.add(100 * MS, 5_000 * MS)
    receipts.add(200 * MS, 0)  # a reset of the simulation
    receipts.add(250 * MS, 10 * MS)
    receipts.add(240 * MS, 99 * MS)  # an older receipt than the last: ignored
    assert receipts.backward_jumps == 1
    assert [receipts.at(t * MS) for t in (150, 210, 260)] == [5_000 * MS, 0, 10 * MS]


def test_old_receipts_are_cut_but_the_mapping_stays_whole() -> None:
    receipts = ClockReceipts(keep_s=1.0)
    for i in range(5000):  # 5 s of receipts, 1 ms apart, keeping about 1 s
        receipts.add(i * MS, 2 * i * MS)
    walls, clocks = receipts._samples  # noqa: SLF001 - the bound is what is tested
    assert len(walls) == len(clocks) <= 2001
    assert receipts.at(4999 * MS) == 9998 * MS
    assert receipts.at(4500 * MS) == 9000 * MS


def test_reading_while_another_thread_adds_never_fails_or_goes_back() -> None:
    receipts = ClockReceipts(keep_s=0.05)
    receipts.add(0, 0)
    stop = threading.Event()
    errors: list[BaseException] = []

    def read() -> None:
        try:
            while not stop.is_set():
                value = receipts.at(10**12)
                assert value is not None and value >= 0
        except BaseException as exc:  # noqa: BLE001 - reported below
            errors.append(exc)
    reader = threading.Thread(target=read)
    reader.start()
    for i in range(1, 200_000):
        receipts.add(i * 1000, i)
    stop.set()
    reader.join()
    assert not errors
    assert receipts.at(10**12) == 199_999


@pytest.mark.parametrize('little', [True, False])
def test_clock_ns_of_reads_a_cdr_clock(little: bool) -> None:
    header = b'\x00\x01\x00\x00' if little else b'\x00\x00\x00\x00'
    body = struct.pack('<iI' if little else '>iI', 12, 345)
    assert clock_ns_of(header + body) == 12 * 10**9 + 345
    assert clock_ns_of(header + body[:3]) is None
