"""CAN transports: a small abstract bus (`base.Transport`) and one plug-in file per back-end.

* ``base``            :class:`Transport` (send, recv, fileno, shutdown; read, forward), :class:`Frame`
* ``udp_multicast``   python-can's udp_multicast format on a socket of its own (hop limit 0)
* ``python_can_bus``  any other python-can bus, through its public ``recv``/``send``

services/can_bus.py opens them (`open_transport`): the plug-in file named after the python-can
interface if there is one that defines ``open_transport(channel, options)``, else a python-can bus
in :class:`~.python_can_bus.PythonCanTransport`. A new transport is one file here.
"""
from __future__ import annotations

from .base import Frame, Transport, UnreadableFrame
from .python_can_bus import PythonCanTransport


def transport_for(bus) -> Transport:
    """`bus` if it is a :class:`Transport`, else `bus` (python-can's ``recv``/``send``) wrapped in one."""
    return bus if isinstance(bus, Transport) else PythonCanTransport(bus)


__all__ = ["Frame", "PythonCanTransport", "Transport", "UnreadableFrame", "transport_for"]
