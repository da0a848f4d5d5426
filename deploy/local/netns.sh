#!/usr/bin/env bash
# Network namespaces as stand-in hosts for the multi-host harness (deploy/local/run-netns.sh,
# tests/tools/fault_test.py netns-link-cut): host k is the namespace NAME-k, joined to this
# machine by its own veth pair, HOST_END (here, 10.231.k.1/24) <-> NS_END (there, 10.231.k.2/24).
# A worker started with `ip netns exec NAME-k` reaches the coordinator only over that link, so
# `cut` (the host end set down) is a network partition of that host alone.
# Needs root (CAP_NET_ADMIN) and iproute2.
#
# Usage: netns.sh up NAME N       create NAME-1..NAME-N with their links (undone on failure)
#        netns.sh down NAME N     delete them (links go with them); quiet if already gone
#        netns.sh cut NAME K      set K's link down: packets to and from NAME-K are dropped
#        netns.sh heal NAME K     set it up again
#        netns.sh host-ip K       the address of this machine on link K (10.231.K.1)
# NAME: at most 9 characters of [a-z0-9] (interface names are limited to 15).
# CARVEMAP_NETNS_SUBNET: the first two octets of the addresses (default 10.231); `up` refuses
# a subnet this machine already has an address in (another harness running, a real network).
set -euo pipefail
SUBNET=${CARVEMAP_NETNS_SUBNET:-10.231}

usage() { sed -n '2,18p' "$0" | sed 's/^# \{0,1\}//' >&2; exit 2; }
[ $# -ge 2 ] || usage
cmd=$1

check_name() {
  [[ $1 =~ ^[a-z0-9]{1,9}$ ]] || { echo "netns.sh: bad NAME '$1' (1-9 of [a-z0-9])" >&2; exit 2; }
}
check_k() {
  [[ $1 =~ ^[0-9]+$ ]] && [ "$1" -ge 1 ] && [ "$1" -le 250 ] \
      || { echo "netns.sh: bad host number '$1' (1..250)" >&2; exit 2; }
}
host_end() { echo "${1}h$2"; }  # on this machine
ns_end() { echo "${1}n$2"; }    # inside NAME-k

down() {
  local name=$1 n=$2 k
  for k in $(seq 1 "$n"); do
    ip link del "$(host_end "$name" "$k")" 2>/dev/null || true
    ip netns del "$name-$k" 2>/dev/null || true
  done
}

case $cmd in
  up)
    [ $# -eq 3 ] || usage
    name=$2 n=$3
    check_name "$name"; check_k "$n"
    for k in $(seq 1 "$n"); do
      if [ -n "$(ip -4 -o addr show to "$SUBNET.$k.0/24")" ]; then
        echo "netns.sh: $SUBNET.$k.0/24 is already in use on this machine; set" \
             "CARVEMAP_NETNS_SUBNET to other first octets (e.g. 10.232)" >&2
        exit 1
      fi
    done
    trap 'down "$name" "$n"' ERR
    for k in $(seq 1 "$n"); do
      ip netns add "$name-$k"
      ip link add "$(host_end "$name" "$k")" type veth peer name "$(ns_end "$name" "$k")"
      ip link set "$(ns_end "$name" "$k")" netns "$name-$k"
      ip addr add "$SUBNET.$k.1/24" dev "$(host_end "$name" "$k")"
      ip link set "$(host_end "$name" "$k")" up
      ip -n "$name-$k" addr add "$SUBNET.$k.2/24" dev "$(ns_end "$name" "$k")"
      ip -n "$name-$k" link set "$(ns_end "$name" "$k")" up
      ip -n "$name-$k" link set lo up
    done
    trap - ERR
    ;;
  down)
    [ $# -eq 3 ] || usage
    check_name "$2"; check_k "$3"
    down "$2" "$3"
    ;;
  cut | heal)
    [ $# -eq 3 ] || usage
    check_name "$2"; check_k "$3"
    ip link set "$(host_end "$2" "$3")" "$([ "$cmd" = cut ] && echo down || echo up)"
    ;;
  host-ip)
    check_k "$2"
    echo "$SUBNET.$2.1"
    ;;
  *) usage ;;
esac
