"""A fake LMC board behind a pyusb backend (``usb.backend.IBackend``): pyusb's own device,
configuration and endpoint machinery run unchanged on top of it. The board parses the byte
stream (12-byte single commands answered with 8 bytes; 0xC00-byte list packets), executes
lists a few commands per status poll and records what it marked in galvo units.

Faults: ``unplug_after(n)``: after n more transfers every transfer fails with ENODEV as
libusb reports an unplugged device, and the board (its USB power gone) stops and its laser
output drops.
"""

from __future__ import annotations

import errno
import struct
from types import SimpleNamespace

import usb.backend
import usb.core

VENDOR, PRODUCT = 0x9588, 0x9899


def _desc(**kw):
    return SimpleNamespace(extra_descriptors=[], **kw)


class FakeLmcBoard(usb.backend.IBackend):
    def __init__(self, step: int = 4):
        super().__init__()
        self.step = step
        self.writes: list[bytes] = []          # every bulk-out transfer, in order
        self.singles: list[tuple[int, ...]] = []
        self.marks: list[tuple[int, int, int, int, int]] = []   # run, x0, y0, x1, y1
        self.list: list[tuple[int, ...]] = []
        self.pending: list[tuple[int, ...]] = []
        self.exec_pos, self.executing, self.runs = 0, False, 0
        self.port, self.mo, self.enabled = 0, 0, False
        self.pos = (0x8000, 0x8000)
        self.reply = b""
        self.transfers, self.unplug_at = 0, None
        self.unplugged = False

    # -- test controls --------------------------------------------------------------------------
    def unplug_after(self, n: int) -> None:
        self.unplug_at = self.transfers + n

    def laser_output(self) -> bool:
        return not self.unplugged and self.enabled and self.mo == 1 and bool(self.port & 1)

    # -- descriptors ----------------------------------------------------------------------------
    def enumerate_devices(self):
        yield "lmc0"

    def get_device_descriptor(self, dev):
        return _desc(bLength=18, bDescriptorType=1, bcdUSB=0x200, bDeviceClass=0xFF,
                     bDeviceSubClass=0, bDeviceProtocol=0, bMaxPacketSize0=64,
                     idVendor=VENDOR, idProduct=PRODUCT, bcdDevice=0x100, iManufacturer=0,
                     iProduct=0, iSerialNumber=0, bNumConfigurations=1, address=3, bus=1,
                     port_number=1, port_numbers=(1,), speed=usb.util.SPEED_HIGH)

    def get_configuration_descriptor(self, dev, config):
        return _desc(bLength=9, bDescriptorType=2, wTotalLength=32, bNumInterfaces=1,
                     bConfigurationValue=1, iConfiguration=0, bmAttributes=0x80, bMaxPower=50)

    def get_interface_descriptor(self, dev, intf, alt, config):
        return _desc(bLength=9, bDescriptorType=4, bInterfaceNumber=0, bAlternateSetting=0,
                     bNumEndpoints=2, bInterfaceClass=0xFF, bInterfaceSubClass=0,
                     bInterfaceProtocol=0, iInterface=0)

    def get_endpoint_descriptor(self, dev, ep, intf, alt, config):
        addr = (0x02, 0x88)[ep]
        return _desc(bLength=7, bDescriptorType=5, bEndpointAddress=addr, bmAttributes=2,
                     wMaxPacketSize=512, bInterval=0, bRefresh=0, bSynchAddress=0)

    def open_device(self, dev):
        return "handle"

    def close_device(self, dev_handle):
        pass

    def set_configuration(self, dev_handle, config_value):
        pass

    def get_configuration(self, dev_handle):
        return 1

    def claim_interface(self, dev_handle, intf):
        pass

    def release_interface(self, dev_handle, intf):
        pass

    # -- transfers ------------------------------------------------------------------------------
    def _transfer(self) -> None:
        self.transfers += 1
        if self.unplug_at is not None and self.transfers > self.unplug_at:
            self.unplugged, self.executing = True, False
        if self.unplugged:
            raise usb.core.USBError("No such device (it may have been disconnected)",
                                    error_code=-4, errno=errno.ENODEV)

    def bulk_write(self, dev_handle, ep, intf, data, timeout):
        self._transfer()
        data = bytes(data)
        self.writes.append(data)
        if len(data) == 12:
            self._single(struct.unpack("<6H", data))
        elif len(data) == 0xC00:
            self.pending += [struct.unpack_from("<6H", data, i) for i in range(0, 0xC00, 12)]
        else:
            raise usb.core.USBError("bad transfer length", errno=errno.EIO)
        return len(data)

    def bulk_read(self, dev_handle, ep, intf, buff, timeout):
        self._transfer()
        if not self.reply:
            raise usb.core.USBTimeoutError("Operation timed out", errno=errno.ETIMEDOUT)
        n = len(self.reply)
        buff[:n] = type(buff)("B", self.reply)
        self.reply = b""
        return n

    # -- the board ------------------------------------------------------------------------------
    def _single(self, cmd: tuple[int, ...]) -> None:
        op = cmd[0]
        self.singles.append(cmd)
        if op == 0x07 and self.executing:                       # GetVersion: status poll
            self._advance()
        if op == 0x12:                                          # ResetList
            self.list, self.pending, self.executing = [], [], False
        elif op == 0x19:                                        # SetEndOfList
            self.list += self.pending
            self.pending = []
        elif op == 0x05:                                        # ExecuteList
            self.executing, self.exec_pos = True, 0
            self.runs += 1
        elif op == 0x1F:                                        # StopExecute
            self.executing = False
        elif op == 0x21:                                        # WritePort
            self.port = cmd[1]
        elif op == 0x33:                                        # Fiber_SetMo
            self.mo = cmd[1]
        elif op in (0x02, 0x04):
            self.enabled = op == 0x04
        status = 0x20 | (0x04 if self.executing else 0)
        self.reply = struct.pack("<4H", op, 0, 0, status)

    def _advance(self) -> None:
        for _ in range(self.step):
            if self.exec_pos >= len(self.list):
                self.executing = False
                return
            op, *p = self.list[self.exec_pos]
            self.exec_pos += 1
            if op == 0x8002:                                    # end of list
                self.exec_pos = len(self.list)
                break
            if op == 0x8005 and self.laser_output():
                self.marks.append((self.runs, *self.pos, p[0], p[1]))
            if op in (0x8001, 0x8005):
                self.pos = (p[0], p[1])
            elif op == 0x8011:
                self.port = p[0]
        if self.exec_pos >= len(self.list):
            self.executing = False
