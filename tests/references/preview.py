"""Independent closed forms for the preview and time-lapse tests: the sRGB encoding and the sun's
position from Meeus' formulas (not pvlib, which skyref uses)."""

import math


def srgb8(linear):
    """8-bit sRGB of a display value in [0, 1] (IEC 61966-2-1)."""
    encoded = 12.92 * linear if linear <= 0.0031308 else 1.055 * linear ** (1 / 2.4) - 0.055
    return round(encoded * 255)


def solar_position(utc, latitude, longitude):
    """(zenith, azimuth) in degrees, geometric, from Meeus' low-precision solar coordinates
    (Astronomical Algorithms, ch. 25; ~0.01 deg) and the mean sidereal time (ch. 12)."""
    jd = utc.timestamp() / 86400.0 + 2440587.5
    t = (jd - 2451545.0) / 36525.0
    mean_longitude = 280.46646 + 36000.76983 * t
    anomaly = math.radians(357.52911 + 35999.05029 * t)
    centre = ((1.914602 - 0.004817 * t) * math.sin(anomaly) + 0.019993 * math.sin(2 * anomaly)
              + 0.000289 * math.sin(3 * anomaly))
    omega = math.radians(125.04 - 1934.136 * t)
    apparent = math.radians(mean_longitude + centre - 0.00569 - 0.00478 * math.sin(omega))
    obliquity = math.radians(23.439291 - 0.0130042 * t + 0.00256 * math.cos(omega))
    right_ascension = math.atan2(math.cos(obliquity) * math.sin(apparent), math.cos(apparent))
    declination = math.asin(math.sin(obliquity) * math.sin(apparent))
    sidereal = 280.46061837 + 360.98564736629 * (jd - 2451545.0)
    hour = math.radians(sidereal + longitude) - right_ascension
    phi = math.radians(latitude)
    elevation = math.asin(math.sin(phi) * math.sin(declination)
                          + math.cos(phi) * math.cos(declination) * math.cos(hour))
    azimuth = math.atan2(math.sin(hour), math.cos(hour) * math.sin(phi) - math.tan(declination) * math.cos(phi))
    return 90.0 - math.degrees(elevation), (math.degrees(azimuth) + 180.0) % 360.0
