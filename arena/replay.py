"""Replay files: top-down frames collected during a race, saved as an animated GIF."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from arena.render import TopDownRenderer
from tracks.track import Track


class ReplayWriter:
    """Collects every ``every``-th frame of a race and writes a GIF (imageio)."""

    def __init__(self, track: Track, width: int = 480, every: int = 2) -> None:
        self.renderer = TopDownRenderer(track, width=width)
        self.every = every
        self.frames: list[np.ndarray] = []
        self._count = 0

    def add(self, env) -> None:
        """Add the env's current scene (called after each step)."""
        from arena.env import CAR_COLORS

        self._count += 1
        if self._count % self.every:
            return
        poses = env.car_poses()
        cars = [
            (poses[a], CAR_COLORS[i]) for i, a in enumerate(env.possible_agents) if a in env.agents
        ]
        self.frames.append(
            self.renderer.frame(cars=cars, bots=env.bot_poses(), obstacles=env.obstacle_poses())
        )

    def save(self, path: str | Path, fps: float = 7.5) -> Path:
        """Write the collected frames as a looping GIF."""
        import imageio.v2 as imageio

        path = Path(path)
        frames = self.frames or [self.renderer.background]
        imageio.mimsave(path, frames, duration=1.0 / fps, loop=0)
        return path
