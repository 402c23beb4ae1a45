"""Exports of attacked scenes for other tools (`adversary export`): CommonRoad scenario XML."""
