"""USB HID data gloves through hidapi, with report decoders as plug-ins: another glove is a new
decoder (register_decoder), not a new driver.

The 5DT Data Glove Ultra decoder follows the report VRPN's vrpn_Analog_5dtUSB decodes: 64-byte
reports holding 16 big-endian signed 16-bit words, each sensor a 12-bit value (scale 1/4096);
the 14-sensor glove uses the first 14 words, the 5-sensor glove every third word (0, 3, ..,
12). Vendor id 0x5D70; product ids 0x00/0x01 (14 sensors, right/left) and 0x10/0x11 (5
sensors, right/left)."""

import struct
import time

import numpy as np

from .device import Device, DeviceError

DECODERS = {}


class ReportDecoder:
    """Turns one HID input report into raw sensor values; names the gloves it understands."""

    name = "decoder"
    vendor_id = None
    product_ids = ()
    layout = ()
    resolution = 0.0  # one step of the decoded values

    def decode(self, report):
        raise NotImplementedError

    def matches(self, vendor_id, product_id):
        return vendor_id == self.vendor_id and (not self.product_ids or product_id in self.product_ids)


def register_decoder(decoder):
    DECODERS[decoder.name] = decoder
    return decoder


# 5DT sensor order (14 sensors): near and far joint of each finger, then the abduction between
# neighbours; as (finger, bone index along the chain, axis) for the calibration.
LAYOUT_5DT_14 = (
    ("thumb", 1, "flex"), ("thumb", 2, "flex"), ("thumb", 0, "abduct"),
    ("index", 0, "flex"), ("index", 1, "flex"), ("index", 0, "spread"),
    ("middle", 0, "flex"), ("middle", 1, "flex"), ("ring", 0, "spread"),
    ("ring", 0, "flex"), ("ring", 1, "flex"), ("pinky", 0, "spread"),
    ("pinky", 0, "flex"), ("pinky", 1, "flex"),
)
LAYOUT_5DT_5 = (("thumb", 1, "flex"), ("index", 0, "flex"), ("middle", 0, "flex"), ("ring", 0, "flex"),
                ("pinky", 0, "flex"))


class FiveDTUltra(ReportDecoder):
    vendor_id = 0x5D70
    resolution = 1.0 / 4096.0

    def __init__(self, sensors=14):
        if sensors not in (5, 14):
            raise DeviceError("the 5DT Data Glove Ultra has 5 or 14 sensors")
        self.sensors = sensors
        self.name = f"5dt_ultra_{sensors}"
        self.product_ids = (0x00, 0x01) if sensors == 14 else (0x10, 0x11)
        self.layout = LAYOUT_5DT_14 if sensors == 14 else LAYOUT_5DT_5

    def decode(self, report):
        report = bytes(report)
        if len(report) != 64:
            raise ValueError(f"a 5DT Ultra report has 64 bytes, not {len(report)}")
        words = np.array(struct.unpack(">16h", report[:32]), float) / 4096.0
        return words[:14] if self.sensors == 14 else words[0:13:3]

    @staticmethod
    def encode(values, sensors=14):
        """A report as the glove sends it (for tests and demos without the glove)."""
        words = np.zeros(16)
        if sensors == 14:
            words[:14] = values
        else:
            words[0:13:3] = values
        raw = np.clip(np.rint(words * 4096.0), -32768, 32767).astype(int)
        return struct.pack(">16h", *raw) + bytes(32)


register_decoder(FiveDTUltra(14))
register_decoder(FiveDTUltra(5))


def import_hid():
    try:
        import hid
    except ImportError:
        raise DeviceError("hidapi is not installed: the USB data glove needs it (pip install hidapi, or the "
                          "extension's bundled hidapi wheel)") from None
    return hid


class HidGlove(Device):
    """A USB HID glove read through hidapi with a registered report decoder."""

    kind = "hid_glove"

    def __init__(self, name, decoder="5dt_ultra_14", path=None, hand="R", timeout_ms=50, watchdog=1.0, **kw):
        super().__init__(name, **kw)
        if decoder not in DECODERS:
            raise DeviceError(f"no HID glove decoder '{decoder}' (known: {', '.join(sorted(DECODERS))})")
        self.decoder = DECODERS[decoder]
        self.path, self.hand, self.timeout_ms, self.watchdog = path, hand, timeout_ms, watchdog
        self._dev = None
        self._last = 0.0

    def _open(self):
        hid = import_hid()
        infos = [d for d in hid.enumerate() if self.decoder.matches(d["vendor_id"], d["product_id"])]
        if self.path:
            infos = [d for d in infos if d["path"] in (self.path, self.path.encode())]
        if not infos:
            raise DeviceError(f"{self.name}: no USB glove for decoder '{self.decoder.name}' is plugged in "
                              f"(vendor 0x{self.decoder.vendor_id:04x})")
        dev = hid.device()
        dev.open_path(infos[0]["path"])
        self._dev = dev
        self._last = time.perf_counter()

    def _read(self):
        report = self._dev.read(64, self.timeout_ms)
        now = time.perf_counter()
        if not report:
            if now - self._last > self.watchdog:
                raise DeviceError(f"{self.name}: no report for {self.watchdog:g} s")
            return []
        self._last = now
        try:
            raw = self.decoder.decode(report)
        except ValueError as exc:
            self.discarded_bytes += len(report)
            self.resyncs += 1
            self.last_error = str(exc)
            return []
        return [self.make_sample("glove", "glove", {"raw": raw, "model": self.decoder.name, "hand": self.hand},
                                 now)]

    def _close(self):
        dev, self._dev = self._dev, None
        if dev is not None:
            dev.close()
