"""A late reply to an abandoned attempt is never taken for the answer to the next command.

The instrument here is scripted by the test on a real pseudo-terminal (`os.openpty`), so the timing that
exposed this is deterministic: the first ``LEV?`` is answered only once the driver has sent it again, and the
two answers then arrive 0.1 s apart (an instrument catching up under load). Before the transport waited for a
quiet line after a retried exchange, the second ``0.3`` was read as the next query's answer, the identity.
"""

from __future__ import annotations

import os
import threading
import tty

import pytest

from uwlab.drivers.serial.transport import LineTransport

IDENTITY = "ACME,LED-1,0001,1.0"


class SlowInstrument(threading.Thread):
    """Answers ``*IDN?`` at once; leaves the first ``LEV?`` unanswered until it is sent again, then answers
    both in order, 0.1 s apart."""

    def __init__(self, master: int):
        super().__init__(daemon=True)
        self.master = master
        self.received: list[str] = []
        self.stop = threading.Event()

    def run(self) -> None:
        buffer = b""
        while not self.stop.is_set():
            try:
                buffer += os.read(self.master, 256)
            except OSError:
                return
            while b"\n" in buffer:
                line, _, buffer = buffer.partition(b"\n")
                self.received.append(line.decode())
                if line == b"*IDN?":
                    os.write(self.master, IDENTITY.encode() + b"\n")
                elif line == b"LEV?" and self.received.count("LEV?") == 2:
                    os.write(self.master, b"0.3\n")
                    self.stop.wait(0.1)
                    os.write(self.master, b"0.3\n")


@pytest.fixture
def slow_port():
    master, slave = os.openpty()
    tty.setraw(slave)
    instrument = SlowInstrument(master)
    instrument.start()
    yield os.ttyname(slave), instrument
    instrument.stop.set()
    os.close(slave)
    os.close(master)


def test_the_second_answer_to_a_retried_query_is_not_the_next_querys(slow_port):
    port, instrument = slow_port
    with LineTransport(port, timeout_s=0.3, retries=2, reopen_s=0.5) as transport:
        assert transport.query("LEV?", float) == 0.3
        assert transport.query("*IDN?") == IDENTITY
    assert instrument.received == ["LEV?", "LEV?", "*IDN?"]
