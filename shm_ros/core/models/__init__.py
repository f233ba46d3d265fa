"""Structural models: girder on bearings, shear building, user matrices; reduction and expansion."""
