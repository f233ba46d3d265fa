"""Roving sensors on a robot (docs/interfaces.md section 8): where the sensor is (a tf buffer),
setups cut where it dwells, setups merged into global mode shapes, and advice to the robot."""
