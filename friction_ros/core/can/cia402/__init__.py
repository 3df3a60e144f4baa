"""CiA 402 (CANopen drive profile) over CiA 301: master side, SYNC producer, emulated drive.

* :mod:`.master` — one axis in cyclic synchronous torque mode (start-up, PDO exchange, state machine, faults)
* :mod:`.network` — several axes on one python-can bus with one SYNC per control period
* :mod:`.emulator` — a CiA 402 drive built on ``canopen.LocalNode`` with a project plant behind it
* :mod:`.frames`, :mod:`.objects`, :mod:`.state_machine`, :mod:`.units`, :mod:`.sdo_script`, :mod:`.config`
"""

from friction_ros.core.can.cia402.config import Cia402Config
from friction_ros.core.can.cia402.master import Cia402Master, Cia402Telemetry
from friction_ros.core.can.cia402.network import Cia402Network, SyncProducer
from friction_ros.core.can.cia402.state_machine import State

__all__ = ["Cia402Config", "Cia402Master", "Cia402Network", "Cia402Telemetry", "State", "SyncProducer"]
