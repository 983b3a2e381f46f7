"""Tests of the robot-description layer (urdaemon.description)."""
