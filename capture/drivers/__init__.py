"""Sensor drivers behind one interface (:mod:`capture.drivers.base`) and their registry.

Driver modules that need an SDK are imported lazily (``base.DRIVER_MODULES``), so importing
this package never imports pyrealsense2 or depthai.
"""
from capture.drivers.base import (DeviceInfo, Driver, DriverListing, Frame, SensorConfig, SensorDescription,
                                  StreamDescription, StreamSettings, driver_class, enumerate_devices, host_clock_us,
                                  known_drivers, register)

__all__ = ["DeviceInfo", "Driver", "DriverListing", "Frame", "SensorConfig", "SensorDescription", "StreamDescription",
           "StreamSettings", "driver_class", "enumerate_devices", "host_clock_us", "known_drivers", "register"]
