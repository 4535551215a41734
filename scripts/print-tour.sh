#!/usr/bin/env bash
# Printed by `make run` before the daemon starts: how to query it.
listen=${1:-127.0.0.1:50051}
metrics=${2:-127.0.0.1:9464}
cat <<TOUR

animspaced is starting on ${listen} with the bundled demo repository: eight models, the bending
arm in each kind and the Cornell box (docs/DEMO.md).
In another terminal:

  build/bin/animspace --server ${listen} health          # SERVING once the models are loaded
  build/bin/animspace --server ${listen} list            # models and versions
  build/bin/animspace --server ${listen} describe arm    # sizes, metadata, sections
  build/bin/animspace --server ${listen} describe arm-animspace   # skeleton model with LOD levels
  build/bin/animspace --server ${listen} relight cornell --from 0.1 0.44 0.45 --to 0.45 0.44 0.1 --frames 6 -o /tmp/relight-%02d.png
                                                         # the Cornell box relit from key points, as PNGs
  build/bin/animspace --server ${listen} server-info     # limits and implemented RPCs
  build/bin/animspace --server ${listen} stats           # per-model requests, poses, hit rates, latency (ms)
  curl -s http://${metrics}/metrics                      # Prometheus metrics

Stop it with Ctrl-C (in-flight calls finish first).

TOUR
