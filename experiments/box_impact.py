"""The box impacting a supported beam (paper section 4.2, Figs. 14-17), shared and frictional contact.

Usage: ``python experiments/box_impact.py [OUT_DIR]`` (default results/box_impact).
"""

import sys
import warnings

from femgrid_mpm.reproduce import box_impact

if __name__ == "__main__":
    warnings.simplefilter("ignore")  # expected events (negative masses under "warn") are in the table
    out = sys.argv[1] if len(sys.argv) > 1 else "results/box_impact"
    if out.startswith("-"):  # an option (--help) is no output directory
        sys.exit("usage: python experiments/box_impact.py [OUT]  (default results/box_impact): the case's figures and table.md in OUT")
    box_impact.run(out)
    print(open(f"{out}/table.md").read())
