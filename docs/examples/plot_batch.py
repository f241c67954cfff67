"""
Many frames: ``reconstruct_many``
=================================

:func:`clfza.reconstruct_many` reconstructs a sequence of frames: in this process (as here),
or on Dask workers (``workers=N`` for a local cluster of processes, ``scheduler=`` or
``client=`` for an existing one). ``frames_per_solve`` solves consecutive frames of one camera
together (one launch for several frames); ``"auto"`` chooses per device. Each frame comes
back as a :class:`~clfza.distributed.FrameResult` with its record, in the frames' order.
"""

import matplotlib.pyplot as plt
import numpy as np
from skimage import data

import clfza

cam = clfza.Camera.preset("simulation")
scene = data.camera() / 255.0
# four raw frames (what a sensor records) of a scene moving to the right, 8 pixels a frame
frames = [clfza.simulate(np.roll(scene, 8 * k, axis=1), cam, object_width=20.0).frame
          for k in range(4)]

res = clfza.reconstruct_many(frames, cam, "admm", iters=30, model="tf", frames_per_solve=2,
                             return_images=True)
for r in res.results:
    t = r.record["timings_s"]
    print(f"frame {r.index}: ok={r.ok} compile {t['compile']:.3f} s, plan {t['plan']:.3f} s, "
          f"solve {t['solve']:.3f} s, {r.record['iterations']} iterations")

fig, axes = plt.subplots(1, len(frames), figsize=(3 * len(frames), 3.2))
for ax, r in zip(axes, res.results):
    ax.imshow(r.image, cmap="gray")
    ax.set_title(f"frame {r.index}", fontsize=9)
    ax.axis("off")
fig.tight_layout()
plt.show()
