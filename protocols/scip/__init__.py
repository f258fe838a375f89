"""Hokuyo URG-04LX over SCIP 2.0 (and the SCIP 1.1 boot option), sans-I/O."""

from protocols.scip.device import UrgDevice

__all__ = ["UrgDevice"]
