"""A helper process that draws part of a video (`hexa_mjx.evaluation.video.render_video`).

Reads (MjModel, frames, drawing settings) pickled on stdin from its parent and writes the frames'
raw RGB bytes to stdout. Only `render_video` starts it.
"""

import pickle
import sys

from hexa_mjx.evaluation.video import render_frames

if __name__ == "__main__":
    model, frames, draw = pickle.load(sys.stdin.buffer)
    sys.stdout.buffer.write(render_frames(model, frames, **draw).tobytes())
    sys.stdout.buffer.flush()
