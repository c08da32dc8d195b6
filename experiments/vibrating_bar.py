"""The paper's vibrating bar (Figs. 4-8) and its period/energy/time table.

Usage: ``python experiments/vibrating_bar.py [OUT_DIR]`` (default results/vibrating_bar).
"""

import sys

from femgrid_mpm.reproduce import vibrating_bar

if __name__ == "__main__":
    out = sys.argv[1] if len(sys.argv) > 1 else "results/vibrating_bar"
    if out.startswith("-"):  # an option (--help) is no output directory
        sys.exit("usage: python experiments/vibrating_bar.py [OUT]  (default results/vibrating_bar): the case's figures and table.md in OUT")
    vibrating_bar.run(out)
    print(open(f"{out}/table.md").read())
