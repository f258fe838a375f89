"""SICK CoLa (the SOPAS command language) over TCP: CoLa-A (ASCII) and CoLa-B (binary), sans-I/O.

`ColaDevice` is one client's session with a `ColaUnit` (a scanner's settings,
which outlive sessions until the unit is rebooted); docs/cola.md describes
the telegrams and the choices made where SICK's listings are silent.
"""

from protocols.cola.device import ColaDevice, ColaUnit, UnitModel

__all__ = ["ColaDevice", "ColaUnit", "UnitModel"]
