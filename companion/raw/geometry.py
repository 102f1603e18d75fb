"""Receiver-to-satellite geometry: ENU rotation, elevation, troposphere model."""

from __future__ import annotations

import math

import numpy as np

from companion.nav.frames import ecef_to_geodetic
from companion.raw.orbit import FloatArray


def enu_rotation(lat_rad: float, lon_rad: float) -> FloatArray:
    """Rows: East, North, Up unit vectors in ECEF at (lat, lon)."""
    sl, cl = math.sin(lat_rad), math.cos(lat_rad)
    so, co = math.sin(lon_rad), math.cos(lon_rad)
    return np.array([[-so, co, 0.0], [-sl * co, -sl * so, cl], [cl * co, cl * so, sl]])


def elevation_rad(rx_ecef_m: FloatArray, sat_ecef_m: FloatArray) -> float:
    lat, lon, _ = ecef_to_geodetic(*rx_ecef_m)
    los = sat_ecef_m - rx_ecef_m
    enu = enu_rotation(lat, lon) @ (los / np.linalg.norm(los))
    return math.asin(max(-1.0, min(1.0, float(enu[2]))))


def saastamoinen_m(
    height_m: float, lat_rad: float, elevation: float, humidity: float = 0.7
) -> float:
    """Tropospheric slant delay: Saastamoinen's model with its own zenith-angle mapping.

    Standard atmosphere for pressure and temperature at ``height_m`` (as RTKLIB's
    ``tropmodel``); valid from 0 to 10 km and above a few degrees of elevation.
    """
    if elevation <= 0.0:
        return 0.0
    h = min(max(height_m, 0.0), 10_000.0)
    pres = 1013.25 * (1.0 - 2.2557e-5 * h) ** 5.2568
    temp = 15.0 - 6.5e-3 * h + 273.16
    e = 6.108 * humidity * math.exp((17.15 * temp - 4684.0) / (temp - 38.45))
    z = math.pi / 2.0 - elevation
    trph = 0.0022768 * pres / (1.0 - 0.00266 * math.cos(2.0 * lat_rad) - 0.00028 * h / 1e3)
    trph /= math.cos(z)
    trpw = 0.002277 * (1255.0 / temp + 0.05) * e / math.cos(z)
    return trph + trpw
