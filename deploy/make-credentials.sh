#!/bin/sh
# Credentials of a sharedctl site: a private CA, the router's TLS certificate, one client
# certificate and one password per role (operator, controller, robot, observer; per named operator), the router's
# password dictionary, and ready Zenoh configurations that use them.
#
#   deploy/make-credentials.sh [DIR] [sharedctl credentials options...]
#
# DIR defaults to /etc/sharedctl/credentials. Written there (keys and passwords mode 0600):
#   ca.pem ca-key.pem              site CA (keep ca-key.pem offline once done; needed only to issue more)
#   router.pem router-key.pem      router certificate, CN router, SAN localhost and 127.0.0.1
#   ROLE.pem ROLE-key.pem          client certificate per role, CN = role (the ACL matches it)
#   ROLE.password passwords.txt    the role's password; the router's usrpwd dictionary (user:password)
#   router.json5 ROLE.json5        `sharedctl router --config router.json5`, `--zenoh-config ROLE.json5`
#                                  (paths inside are relative to the file; see deploy/zenoh/*.json5)
#   NAME.signing-key.pem           each operator's Ed25519 key (`sharedctl console --signing-key`)
#   operators.toml                 the operators' public keys and robots (`sharedctl controller --operators`)
# Options: --operator NAME[=ROBOT,...] (one set of credentials and a signing key per person, allowed
# those robots only; repeatable; default one operator named `operator`, every robot), --host H
# (router certificate names, repeatable), --days N, --endpoint EP (default tls/127.0.0.1:7447, or
# $SHAREDCTL_ROUTER_ENDPOINT). Running it again replaces everything: every process then needs its
# new files.
set -eu
DIR=${1:-/etc/sharedctl/credentials}
[ $# -gt 0 ] && shift
ENDPOINT=${SHAREDCTL_ROUTER_ENDPOINT:-tls/127.0.0.1:7447}
umask 077
if command -v sharedctl >/dev/null 2>&1; then
    SHAREDCTL=sharedctl
else
    SHAREDCTL="${PYTHON:-python3} -m sharedctl.services.cli"
fi
mkdir -p "$DIR"
# shellcheck disable=SC2086  # $SHAREDCTL may be "python3 -m ..."
$SHAREDCTL credentials "$DIR" --configs --endpoint "$ENDPOINT" "$@"
for f in "$DIR"/*.pem; do
    case $f in
        *-key.pem) chmod 0600 "$f" ;;       # TLS keys and operators' signing keys (NAME.signing-key.pem)
        *) chmod 0644 "$f" ;;               # certificates
    esac
done
chmod 0600 "$DIR"/*.password "$DIR/passwords.txt" "$DIR"/*.json5
chmod 0644 "$DIR/operators.toml"
