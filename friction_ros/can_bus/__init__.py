"""CAN bus transports that do I/O (sockets), kept out of the pure core.

:mod:`~friction_ros.can_bus.local_bus`: the ``friction_local`` python-can interface, a CAN bus
between the processes of one machine over Unix datagram sockets.
"""
