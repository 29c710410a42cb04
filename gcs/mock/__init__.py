"""The mock drone: a separate process that speaks MAVLink and behaves like a PX4 quadrotor."""
