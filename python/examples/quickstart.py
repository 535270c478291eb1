"""The README's quick-start scene: a rounded cube drilled along three axes, saved as a mesh.

    python examples/quickstart.py [out.stl]
"""
import sys

from sdfprune import X, Y, Z, box, cylinder, sphere

f = sphere(1) & box(1.5)
c = cylinder(0.5, height=3)
f -= c.orient(X) | c.orient(Y) | c.orient(Z)
f.save(sys.argv[1] if len(sys.argv) > 1 else "out.stl")
print(f([[0.6, 0.6, 0.0]]))  # [-0.10000002]: negative inside, 0.1 from the drilled hole's wall
