"""Force-sensor conditioning: tare, gravity compensation of the tool below a flange sensor, and
detection of an untared bias (``docs/study.md``, "Sensor conditioning").

Reading model of a sensor, per sample, in sensor axes about its origin::

    W_meas(t) = W_process(t) + b + W_g(R(t))            b: zero offset (6,), constant
    W_g(R)    = [ m gₛ ;  r_c × m gₛ ],   gₛ = R_world_sensorᵀ g_world

``m`` is the mass hanging below the sensor (tool + holder), ``r_c`` its centre of gravity in the
sensor frame, ``g_world = (0, 0, −9.80665) m/s²`` along −z of the robot base (a floor-mounted
robot; the work frame when there is no robot).
"""

from roboisf.sensor.conditioning import (
    G_WORLD,
    Conditioning,
    ToolLoad,
    UnloadedStretch,
    condition_wrench,
    gravity_wrench,
    identify_tool_load,
    unloaded_samples,
    unloaded_stretches,
)

__all__ = [
    "G_WORLD",
    "Conditioning",
    "ToolLoad",
    "UnloadedStretch",
    "condition_wrench",
    "gravity_wrench",
    "identify_tool_load",
    "unloaded_samples",
    "unloaded_stretches",
]
