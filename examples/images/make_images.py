"""Remake the example images of this folder (the README's `fourier` and `generate cri --images` inputs).

    python examples/images/make_images.py

They are synthetic, made by grainforge itself (``grainforge.viz.demo.example_images``): there are no
real micrographs in this repository.  Same code, same pixels (``tests/project/test_doc_paths.py`` checks).
"""

from pathlib import Path

from grainforge.viz.demo import example_images

if __name__ == "__main__":
    for p in example_images(Path(__file__).resolve().parent):
        print(p)
