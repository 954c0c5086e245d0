"""A tiny stand-in for an external solver, used by the tests.

Reads ``key = value`` lines, writes a trajectory of a parcel sliding onto a belt (speed 1 m/s)
with friction mu_d_BePa: it accelerates at mu * g until it reaches the belt speed.
Special values: mu_d_BePa = 0.11 exits with an error, 0.12 sleeps for 30 s, 0.13 writes no
transit time.
"""

import sys
import time

params = {}
with open(sys.argv[1]) as fh:
    for line in fh:
        if "=" in line:
            key, value = line.split("=", 1)
            params[key.strip()] = value.strip()
mu = float(params["mu_d_BePa"])
if mu == 0.11:
    print("solver: diverged at step 42", file=sys.stderr)
    sys.exit(3)
if mu == 0.12:
    time.sleep(30)
a = mu * 9.81
rows = ["t,x,y,theta"]
x = v = 0.0
for i in range(61):
    t = i / 60
    rows.append(f"{t:.6f},{x:.9f},0,0.1")
    v = min(1.0, v + a / 60)
    x += v / 60
with open(sys.argv[2], "w") as fh:
    fh.write("\n".join(rows) + "\n")
if mu != 0.13:  # 0.13: no transit time written, as for a parcel that never crosses
    with open("transit.txt", "w") as fh:
        fh.write(f"{1.0 / max(v, 1e-9):.6f}\n")
