"""Fault kinds of the emulated lab (the registry and its rules: emulator.faults.base).

The registry (:data:`KINDS`) holds the shipped kinds, declared in emulator.faults.base, and
finds the kinds of installed packages (entry-point group ``navtwin.faults``) when asked.
"""
from .base import (ENTRY_POINTS, KINDS, MODELS, AnchorFault, BoardFault, DeviceFault, Fault, FaultError,
                   LineFault, RouterFault, acting_on, register, unregister)
from .anchor_outage import AnchorOutage
from .nlos import Nlos
from .link_loss import LinkLoss
from .link_fade import LinkFade
from .range_value_error import RangeValueError
from .board_reset import BoardReset
from .coordinator_reset import CoordinatorReset
from .router_rejoin import RouterRejoin
from .bit_errors import BitErrors
from .byte_drop import ByteDrop
from .byte_duplicate import ByteDuplicate
from .byte_insert import ByteInsert
from .garbage import Garbage
from .burst_loss import BurstLoss
from .latency import Latency
from .bandwidth import Bandwidth
from .slicing import Slicing
from .stuck import Stuck

__all__ = ["ENTRY_POINTS", "KINDS", "MODELS", "AnchorFault", "BoardFault", "RouterFault", "DeviceFault", "Fault", "FaultError", "LineFault",
           "acting_on", "register", "unregister", "AnchorOutage", "Nlos",
           "LinkLoss", "LinkFade", "RangeValueError", "BoardReset", "CoordinatorReset", "RouterRejoin",
           "BitErrors", "ByteDrop", "ByteDuplicate", "ByteInsert", "Garbage", "BurstLoss",
           "Latency", "Bandwidth", "Slicing", "Stuck"]
