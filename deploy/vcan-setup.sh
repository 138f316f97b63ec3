#!/usr/bin/env bash
# Create virtual CAN interfaces for sharedctl on a Linux host whose kernel has the vcan module.
# Usage: sudo deploy/vcan-setup.sh [NAME ...]      (default: vcan0)
# With vcan0 present, `sharedctl robot` and `sharedctl controller` default to SocketCAN on it;
# without it they use python-can's udp_multicast with hop_limit=0 (host-local).
set -euo pipefail
names=("$@")
[ ${#names[@]} -gt 0 ] || names=(vcan0)
if ! modprobe vcan 2>/dev/null; then
  echo "vcan-setup: cannot load the vcan kernel module (kernel without CAN support?)" >&2
  exit 1
fi
for name in "${names[@]}"; do
  if ! ip link show "$name" >/dev/null 2>&1; then
    ip link add dev "$name" type vcan
  fi
  ip link set up "$name"
  echo "vcan-setup: $name is up"
done
