"""The agent folder: the data-only format a trained agent is shared in, and what reads it.

- ``format``: the folder's layout, manifest and SHA-256 checks; writing it atomically;
- ``files``: reading the files of a folder nobody vouches for, bounded and typed;
- ``actor``, ``encoder``: the deployable actor network and its neighbour encoder;
- ``loading``: ``load_policy``, a folder as a policy like the analytic ones;
- ``onnx_policy``: export to ONNX, and a policy that runs the graph.

Reading a folder imports no learning algorithm (no Stable-Baselines3).
"""
