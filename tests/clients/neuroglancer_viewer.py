"""Serves the Neuroglancer client shipped in the `neuroglancer` package on
loopback with a viewer state given as JSON on the command line, prints the
viewer's URL and keeps serving until stdin closes.

    python neuroglancer_viewer.py '{"layers": [...], ...}'
"""

import json
import sys

import neuroglancer


def main():
    state = json.loads(sys.argv[1])
    neuroglancer.set_server_bind_address("127.0.0.1", 0)
    viewer = neuroglancer.Viewer()
    viewer.set_state(neuroglancer.ViewerState(state))
    print(viewer.get_viewer_url(), flush=True)
    # Serve until the test closes our stdin.
    sys.stdin.read()


if __name__ == "__main__":
    main()
