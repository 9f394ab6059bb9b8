"""Errors shared by every device driver.

Each failure a device can show has its own type so callers (the orchestrator, an operator's script)
can react to it: retry on a timeout, re-home after an alarm, reconnect after a disconnect.
"""

from __future__ import annotations


class DeviceError(Exception):
    """Base class for every device failure. ``device`` names the device (e.g. ``"robot"``)."""

    def __init__(self, message: str, *, device: str = "device") -> None:
        super().__init__(f"{device}: {message}")
        self.device = device


class DeviceTimeout(DeviceError):
    """The device did not answer within the timeout."""


class DeviceDisconnected(DeviceError):
    """The connection to the device is gone (port closed, socket reset, cable pulled)."""


class UnexpectedReply(DeviceError):
    """The device answered something the protocol does not allow here (garbled or out of order)."""


class DeviceRefused(DeviceError):
    """The driver refused a command before sending it (e.g. a move outside the travel limits)."""


class DeviceFault(DeviceError):
    """The device reported an error or fault of its own (e.g. GRBL error:N, analyzer error)."""

    def __init__(self, message: str, *, device: str = "device", code: int | None = None) -> None:
        super().__init__(message, device=device)
        self.code = code


# -- Modbus (analyzer) ---------------------------------------------------------------------------
#: Modbus exception codes and their names in the Modbus Application Protocol v1.1b3, section 7
#: (older documents say SLAVE where v1.1b3 says SERVER, e.g. SLAVE_DEVICE_BUSY).
MODBUS_EXCEPTION_NAMES: dict[int, str] = {
    0x01: "ILLEGAL_FUNCTION",
    0x02: "ILLEGAL_DATA_ADDRESS",
    0x03: "ILLEGAL_DATA_VALUE",
    0x04: "SERVER_DEVICE_FAILURE",
    0x05: "ACKNOWLEDGE",
    0x06: "SERVER_DEVICE_BUSY",
    0x07: "NEGATIVE_ACKNOWLEDGE",
    0x08: "MEMORY_PARITY_ERROR",
    0x0A: "GATEWAY_PATH_UNAVAILABLE",
    0x0B: "GATEWAY_TARGET_DEVICE_FAILED_TO_RESPOND",
}


class ModbusExceptionReply(DeviceFault):
    """The device answered a request with a Modbus exception response.

    ``code`` (and ``exception_code``) is the Modbus exception code, ``exception_name`` its name
    from :data:`MODBUS_EXCEPTION_NAMES`, ``request`` a short text of what was asked. Each standard
    code has its own subclass (e.g. :class:`ModbusServerDeviceBusy`), so callers can retry on busy
    and stop on an illegal address; build one with :func:`modbus_exception_reply`.
    """

    def __init__(self, exception_code: int, *, device: str = "device", request: str = "") -> None:
        self.exception_code = exception_code
        self.exception_name = MODBUS_EXCEPTION_NAMES.get(exception_code, "UNKNOWN_EXCEPTION")
        self.request = request
        where = f"{request}: " if request else ""
        super().__init__(
            f"{where}Modbus exception {self.exception_name} (code {exception_code})",
            device=device,
            code=exception_code,
        )


class ModbusIllegalFunction(ModbusExceptionReply):
    """Exception code 1: the device does not support this function code."""


class ModbusIllegalDataAddress(ModbusExceptionReply):
    """Exception code 2: the register address (or address + count) is not valid on the device."""


class ModbusIllegalDataValue(ModbusExceptionReply):
    """Exception code 3: the value written (or the request's structure) is not acceptable."""


class ModbusServerDeviceFailure(ModbusExceptionReply):
    """Exception code 4: the device failed while performing the request."""


class ModbusAcknowledge(ModbusExceptionReply):
    """Exception code 5: accepted, but it takes long; poll for completion."""


class ModbusServerDeviceBusy(ModbusExceptionReply):
    """Exception code 6: the device is busy with a long command; retry later."""


class ModbusNegativeAcknowledge(ModbusExceptionReply):
    """Exception code 7: the device cannot perform the program function now."""


class ModbusMemoryParityError(ModbusExceptionReply):
    """Exception code 8: the device found a parity error in its memory."""


class ModbusGatewayPathUnavailable(ModbusExceptionReply):
    """Exception code 10: a gateway could not route the request."""


class ModbusGatewayTargetNoResponse(ModbusExceptionReply):
    """Exception code 11: a gateway got no answer from the target device."""


_MODBUS_EXCEPTION_TYPES: dict[int, type[ModbusExceptionReply]] = {
    0x01: ModbusIllegalFunction,
    0x02: ModbusIllegalDataAddress,
    0x03: ModbusIllegalDataValue,
    0x04: ModbusServerDeviceFailure,
    0x05: ModbusAcknowledge,
    0x06: ModbusServerDeviceBusy,
    0x07: ModbusNegativeAcknowledge,
    0x08: ModbusMemoryParityError,
    0x0A: ModbusGatewayPathUnavailable,
    0x0B: ModbusGatewayTargetNoResponse,
}


def modbus_exception_reply(
    exception_code: int, *, device: str = "device", request: str = ""
) -> ModbusExceptionReply:
    """Build the error for a Modbus exception reply: the subclass for ``exception_code``.

    Codes outside the standard set give a plain :class:`ModbusExceptionReply`.
    """
    error_type = _MODBUS_EXCEPTION_TYPES.get(exception_code, ModbusExceptionReply)
    return error_type(exception_code, device=device, request=request)


class AnalyzerError(DeviceFault):
    """The analyzer went to its error state; ``code`` is the analyzer's own error code."""
