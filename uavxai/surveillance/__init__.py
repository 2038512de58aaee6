"""What the ownship knows of the traffic: simulated ADS-B and an onboard sensor
(:mod:`.adsb`, :mod:`.sensor`), and a tracker that turns their reports into beliefs with
uncertainty (:mod:`.tracker`)."""

from uavxai.surveillance.adsb import Report, Surveillance, SurveillanceConfig
from uavxai.surveillance.sensor import SensorConfig

__all__ = ["Report", "SensorConfig", "Surveillance", "SurveillanceConfig"]
