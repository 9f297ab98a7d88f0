"""MuJoCo only: a scene as MJCF, torque replay of one combination, whole-plan replay."""
