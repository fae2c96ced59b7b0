#!/usr/bin/env bash
# 100 M triangles, bvh bricks: unlimited vs a quarter budget with and without the subtree tier.
set -euo pipefail
O=${OUTCORE:-$(cd "$(dirname "$0")/.." && pwd)/build/client/outcore}
cd "${1:?usage: subtree_tier_100m.sh WORK_DIR (holding city4883.oc and incoherent.npy from bench/outofcore_bench.py --copies 4883)}"
uptime
$O trace city4883.oc --rays incoherent.npy -o bvh-unl.npy --brick-accel bvh --cache-mb 65536 --threads 2 --repeat 3 --stats-json bvh-unl.json > bvh-unl.log 2>&1
python3 -c "import json;s=json.load(open('bvh-unl.json'));print('unlimited built MiB',s[0]['peak_bytes_resident']/2**20,'cold',s[0]['seconds']['total'],'warm',[r['seconds']['total'] for r in s[1:]])"
built=$(python3 -c "import json;print(int(json.load(open('bvh-unl.json'))[0]['peak_bytes_resident']/2**20/4))")
rm -rf tier && mkdir tier
/usr/bin/time -f "%M KB maxrss %e s" $O trace city4883.oc --rays incoherent.npy -o bvh-tier.npy --brick-accel bvh --cache-mb $built --threads 2 --repeat 3 --subtree-dir tier --stats-json bvh-tier.json > bvh-tier.log 2>&1
tail -1 bvh-tier.log
python3 -c "import json;s=json.load(open('bvh-tier.json'));print('tier budget $built', [(r['seconds']['total'], r['brick_builds'], r.get('subtree_loads')) for r in s])"
cmp bvh-tier.npy bvh-unl.npy && echo TIER_SAME
du -sh tier
/usr/bin/time -f "%M KB maxrss %e s" $O trace city4883.oc --rays incoherent.npy -o bvh-notier.npy --brick-accel bvh --cache-mb $built --threads 2 --repeat 2 --stats-json bvh-notier.json > bvh-notier.log 2>&1
tail -1 bvh-notier.log
python3 -c "import json;s=json.load(open('bvh-notier.json'));print('no tier', [(r['seconds']['total'], r['brick_builds']) for r in s])"
cmp bvh-notier.npy bvh-unl.npy && echo NOTIER_SAME
rm -rf tier
uptime
