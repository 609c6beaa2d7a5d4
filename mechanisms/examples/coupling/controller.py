"""PI controller of the door's hinge angle, as a co-simulation FMU built with pythonfmu.

Build: ``pythonfmu build -f controller.py`` (or :func:`overcon.tooling.cosim.build_controller`),
giving ``DoorController.fmu`` (FMI 2.0 co-simulation; it runs Python inside: the host needs a
Python with pythonfmu's runtime, see docs/coupling.md).

Law (units: rad, rad/s, N·m, s): with the error ``e = setpoint - angle``,

    torque = kp * e + ki * integral(e dt) - kd * rate

a PI controller on the angle with rate feedback (damping from the measured rate, not from a
differentiated error, so a jump of the set point gives no torque spike). The integral is
advanced by the explicit rule of a sampled controller, ``integral += e * h``, with ``e`` read at
the start of the step (the inputs hold over a co-simulation step); the output ``torque`` is
computed at the end of each step from the inputs read at its start (no direct feedthrough: the
loop with the door is no algebraic loop), and before the first step from the start values.

Defaults (kp = 2000 N·m/rad, ki = 8000 N·m/(rad s), kd = 150 N·m s/rad, set point 0.5 rad):
chosen by runs of the example (docs/coupling.md). Near rest the hinge's regularised Coulomb
friction acts like a damper of about 2000 N·m s/rad (1.5 N·m at 7e-4 rad/s), which with small
gains leaves a slow creep towards the set point (kp = 290, ki = 390: still 1.2e-3 rad off at
5 s); gains of the size of that damping settle the door within 1e-3 rad in about 1 s. The
integral takes up the gravity moment of the tilted hinge line and the friction, so no steady
error remains.
"""
from pythonfmu import Fmi2Causality, Fmi2Slave, Fmi2Variability, Real
from pythonfmu.default_experiment import DefaultExperiment


class DoorController(Fmi2Slave):

    author = "overcon"
    description = "PI controller with rate feedback of a door hinge angle (overcon coupling example)"
    default_experiment = DefaultExperiment(start_time=0.0, stop_time=5.0, step_size=0.01)

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.setpoint = 0.5
        self.kp = 2000.0
        self.ki = 8000.0
        self.kd = 150.0
        self.angle = 0.0
        self.rate = 0.0
        self.integral = 0.0
        self.torque = 0.0
        tunable = dict(causality=Fmi2Causality.parameter, variability=Fmi2Variability.tunable)
        self.register_variable(Real("setpoint", description="set angle (rad)", **tunable))
        self.register_variable(Real("kp", description="proportional gain (N.m/rad)", **tunable))
        self.register_variable(Real("ki", description="integral gain (N.m/(rad s))", **tunable))
        self.register_variable(Real("kd", description="rate gain (N.m s/rad)", **tunable))
        self.register_variable(Real("angle", description="measured angle (rad)", causality=Fmi2Causality.input))
        self.register_variable(Real("rate", description="measured rate (rad/s)", causality=Fmi2Causality.input))
        self.register_variable(Real("torque", description="commanded torque (N.m)", causality=Fmi2Causality.output))
        self.register_variable(Real("integral", description="integral of the error (rad s)",
                                    causality=Fmi2Causality.local))

    def _law(self) -> float:
        return self.kp * (self.setpoint - self.angle) + self.ki * self.integral - self.kd * self.rate

    def exit_initialization_mode(self):
        self.torque = self._law()

    def do_step(self, current_time, step_size):
        self.integral += (self.setpoint - self.angle) * step_size
        self.torque = self._law()
        return True
