"""Unit conversions at the edges of gyrojax, in one place.

Inside the code everything is SI: rad/s, m, N, V, s, rad/s for angular frequencies. Degrees per second,
Hz, ppm and LSB appear only in data files, reports and plots, and are converted here.
"""

import math
from typing import TypeVar

import numpy as np
from jax import Array


DEG = math.pi / 180.0
"""One degree in radians."""

EPS0 = 8.8541878128e-12
"""Vacuum permittivity, F/m (CODATA 2018)."""

PPM = 1e-6

Quantity = TypeVar("Quantity", float, np.ndarray, Array)
"""A number or an array of numbers: each conversion returns the type it is given."""


def dps_to_rad_s(rate_dps: Quantity) -> Quantity:
    """Angular rate, deg/s -> rad/s."""
    return rate_dps * DEG


def rad_s_to_dps(rate: Quantity) -> Quantity:
    """Angular rate, rad/s -> deg/s."""
    return rate / DEG


def hz_to_rad_s(f_hz: Quantity) -> Quantity:
    """Frequency, Hz -> angular frequency rad/s."""
    return 2.0 * math.pi * f_hz


def rad_s_to_hz(omega: Quantity) -> Quantity:
    """Angular frequency rad/s -> Hz."""
    return omega / (2.0 * math.pi)


def to_ppm(relative: Quantity) -> Quantity:
    """A relative (dimensionless) quantity -> ppm."""
    return relative / PPM


def from_ppm(ppm: Quantity) -> Quantity:
    """ppm -> a relative (dimensionless) quantity."""
    return ppm * PPM


def scale_factor_to_lsb_per_dps(sf_lsb_per_rad_s: Quantity) -> Quantity:
    """Scale factor, LSB per rad/s -> LSB per deg/s."""
    return sf_lsb_per_rad_s * DEG


def scale_factor_to_lsb_per_rad_s(sf_lsb_per_dps: Quantity) -> Quantity:
    """Scale factor, LSB per deg/s -> LSB per rad/s."""
    return sf_lsb_per_dps / DEG


def wrap_signed(word: int | np.integer, bits: int) -> int:
    """Interpret an unsigned integer as a `bits`-wide two's-complement number."""
    half = 1 << (bits - 1)
    return ((int(word) + half) % (1 << bits)) - half


__all__ = [
    "DEG",
    "EPS0",
    "PPM",
    "dps_to_rad_s",
    "rad_s_to_dps",
    "hz_to_rad_s",
    "rad_s_to_hz",
    "to_ppm",
    "from_ppm",
    "scale_factor_to_lsb_per_dps",
    "scale_factor_to_lsb_per_rad_s",
    "wrap_signed",
]
