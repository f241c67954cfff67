"""Where the host's time goes in one solve: a cProfile of ``clfza.reconstruct`` after a warm-up
(compilation, plans and tuning excluded), on the paper's simulation preset scaled to n x n.

Prints ms per iteration and the functions with the most own time per iteration (calls per
iteration beside them), which separates launch cost (``enqueue_nd_range_kernel``, argument
setting) from waits (``wait``, ``finish``, blocking copies) on a device whose kernels run
asynchronously, such as a GPU::

    python tools/profile_solve.py --method fista --n 512 --iters 100 [--device 0:0] [--top 20]
"""

from __future__ import annotations

import argparse
import cProfile
import pstats
import warnings


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--method", default="fista")
    ap.add_argument("--n", type=int, default=512)
    ap.add_argument("--iters", type=int, default=100)
    ap.add_argument("--mode", default=None, help="TwIST's mode (e.g. paper)")
    ap.add_argument("--device", default=None)
    ap.add_argument("--top", type=int, default=20)
    a = ap.parse_args()
    warnings.simplefilter("ignore")
    from skimage import data
    from skimage.transform import resize

    import clfza
    from clfza import Camera
    from clfza.simulation import simulate

    cam = Camera.preset("simulation")
    cam = cam.with_shape((a.n, a.n), cam.pitch * cam.shape[0] / a.n)
    y = simulate(resize(data.camera() / 255.0, (a.n, a.n)), cam).y
    opts = {"stop": "none"}
    if a.mode:
        opts["mode"] = a.mode
    if a.device:
        opts["device"] = a.device
    clfza.reconstruct(y, cam, a.method, iters=3, **opts)
    prof = cProfile.Profile()
    prof.enable()
    _, info = clfza.reconstruct(y, cam, a.method, iters=a.iters, **opts)
    prof.disable()
    it = info.iterations
    print(f"{a.method} n={a.n}: {1e3 * info.timings['solve'] / it:.3f} ms/iteration "
          f"(solve clock, {it} iterations)")
    stats = pstats.Stats(prof)
    rows = sorted(stats.stats.items(), key=lambda kv: -kv[1][2])[: a.top]
    print(f"{'own ms/it':>10s} {'calls/it':>9s}  function")
    for (file, line, name), (_, calls, own, _, _) in rows:
        where = file.rsplit("/", 2)[-2:] if "/" in file else [file]
        print(f"{1e3 * own / it:10.4f} {calls / it:9.2f}  {name} ({'/'.join(where)}:{line})")


if __name__ == "__main__":
    try:
        main()
    except BrokenPipeError:  # the output piped into `head`: nothing left to say
        import os
        import sys

        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        sys.exit(0)
