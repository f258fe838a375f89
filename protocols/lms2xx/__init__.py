"""SICK LMS200 over the LMS2xx telegram protocol, sans-I/O: framing, CRC and the device state machine."""

from protocols.lms2xx.device import Lms200Device, Mode, ScanSource
from protocols.lms2xx.framing import CorruptTelegram, Telegram, TelegramReader, build_telegram, crc16

__all__ = [
    "CorruptTelegram",
    "Lms200Device",
    "Mode",
    "ScanSource",
    "Telegram",
    "TelegramReader",
    "build_telegram",
    "crc16",
]
