#!/usr/bin/env bash
# Creates the DDS Security material for sl-sensor (docs/operations.md, "DDS Security"):
# an identity CA and a permissions CA, one identity (certificate + key) and
# one signed permissions document per role, and the two signed governance
# documents. Everything is written to OUT (default ./dds-security); keys are
# mode 0600. Uses openssl only.
#
#   bash scripts/dds-security.sh [OUT] [--domain N] [--ns NAMESPACE] [--days D]
#
# Roles (identities):
#   sensor    the daemon: publishes rt/<ns>/* and rr/<ns>/*, reads rq/<ns>/*
#   operator  slctl and clients that control the sensor: writes requests,
#             reads replies, status and data
#   viewer    reads status and data only; its requests are refused
# Governance (choose with SL_DDS_GOVERNANCE when running, see
# config/cyclonedds-security.xml):
#   governance_control  requests, replies and status authenticated, access-
#                       controlled and encrypted; the data topics (points,
#                       images, maps) stay open to any participant, e.g. a
#                       ROS 2 tool without security
#   governance_all      every topic protected and encrypted; participants
#                       without a valid identity are not admitted at all
set -euo pipefail
out=./dds-security domain=0 ns=sl days=3650
while [ $# -gt 0 ]; do
  case $1 in
    --domain) domain=$2; shift 2 ;;
    --ns) ns=$2; shift 2 ;;
    --days) days=$2; shift 2 ;;
    -h|--help) sed -n 2,24p "$0"; exit 0 ;;
    -*) echo "dds-security.sh: unknown option $1" >&2; exit 2 ;;
    *) out=$1; shift ;;
  esac
done
case $domain in ''|*[!0-9]*) echo "dds-security.sh: --domain expects 0..230" >&2; exit 2 ;; esac
[ "$domain" -le 230 ] || { echo "dds-security.sh: --domain expects 0..230" >&2; exit 2; }
case $ns in ''|*[!A-Za-z0-9_/]*) echo "dds-security.sh: --ns expects [A-Za-z0-9_/]+" >&2; exit 2 ;; esac
mkdir -p "$out"
cd "$out"
umask 077
subj_base="/O=sl-sensor/OU=$ns"
not_before=$(date -u +%Y-%m-%dT%H:%M:%S)
not_after=$(date -u -d "+$days days" +%Y-%m-%dT%H:%M:%S)

ca() {  # name
  openssl ecparam -name prime256v1 -genkey -noout -out "$1_ca_key.pem"
  openssl req -x509 -new -key "$1_ca_key.pem" -sha256 -days "$days" -subj "$subj_base/CN=$1 CA" \
    -out "$1_ca.pem" 2>/dev/null
}
ca identity
ca permissions

identity() {  # role
  openssl ecparam -name prime256v1 -genkey -noout -out "$1_key.pem"
  openssl req -new -key "$1_key.pem" -subj "$subj_base/CN=$1" -out "$1.csr" 2>/dev/null
  openssl x509 -req -in "$1.csr" -CA identity_ca.pem -CAkey identity_ca_key.pem -CAcreateserial \
    -sha256 -days "$days" -out "$1_cert.pem" 2>/dev/null
  rm -f "$1.csr"
}

sign() {  # in.xml out.p7s
  openssl smime -sign -in "$1" -text -out "$2" -signer permissions_ca.pem \
    -inkey permissions_ca_key.pem 2>/dev/null
}

topic_rule() {  # expression protected(true|false)
  local p=$2 kind=NONE
  [ "$p" = true ] && kind=ENCRYPT
  cat <<XML
        <topic_rule>
          <topic_expression>$1</topic_expression>
          <enable_discovery_protection>$p</enable_discovery_protection>
          <enable_liveliness_protection>$p</enable_liveliness_protection>
          <enable_read_access_control>$p</enable_read_access_control>
          <enable_write_access_control>$p</enable_write_access_control>
          <metadata_protection_kind>$kind</metadata_protection_kind>
          <data_protection_kind>$kind</data_protection_kind>
        </topic_rule>
XML
}

governance() {  # name protect_data(true|false)
  local allow_unauth=true discovery=NONE
  [ "$2" = true ] && { allow_unauth=false; discovery=ENCRYPT; }
  {
    cat <<XML
<?xml version="1.0" encoding="UTF-8"?>
<dds xmlns:xsi="http://www.w3.org/2001/XMLSchema-instance"
     xsi:noNamespaceSchemaLocation="http://www.omg.org/spec/DDS-SECURITY/20170901/omg_shared_ca_governance.xsd">
  <domain_access_rules>
    <domain_rule>
      <domains><id>$domain</id></domains>
      <allow_unauthenticated_participants>$allow_unauth</allow_unauthenticated_participants>
      <enable_join_access_control>true</enable_join_access_control>
      <discovery_protection_kind>$discovery</discovery_protection_kind>
      <liveliness_protection_kind>$discovery</liveliness_protection_kind>
      <rtps_protection_kind>NONE</rtps_protection_kind>
      <topic_access_rules>
XML
    topic_rule "rq/$ns/*" true
    topic_rule "rr/$ns/*" true
    topic_rule "rt/$ns/status" true
    topic_rule "*" "$2"
    cat <<XML
      </topic_access_rules>
    </domain_rule>
  </domain_access_rules>
</dds>
XML
  } > "$1.xml"
  sign "$1.xml" "$1.p7s"
}
governance governance_control false
governance governance_all true

permissions() {  # role publish-topics subscribe-topics
  {
    cat <<XML
<?xml version="1.0" encoding="UTF-8"?>
<dds xmlns:xsi="http://www.w3.org/2001/XMLSchema-instance"
     xsi:noNamespaceSchemaLocation="http://www.omg.org/spec/DDS-SECURITY/20170901/omg_shared_ca_permissions.xsd">
  <permissions>
    <grant name="$1">
      <subject_name>CN=$1,OU=$ns,O=sl-sensor</subject_name>
      <validity><not_before>$not_before</not_before><not_after>$not_after</not_after></validity>
      <allow_rule>
        <domains><id>$domain</id></domains>
XML
    for kind in publish subscribe; do
      local topics=$2
      [ $kind = subscribe ] && topics=$3
      [ -n "$topics" ] || continue
      echo "        <$kind><topics>"
      for t in $topics; do echo "          <topic>$t</topic>"; done
      echo "        </topics></$kind>"
    done
    cat <<XML
      </allow_rule>
      <default>DENY</default>
    </grant>
  </permissions>
</dds>
XML
  } > "$1_permissions.xml"
  sign "$1_permissions.xml" "$1_permissions.p7s"
}

for role in sensor operator viewer; do identity $role; done
# The ROS 2 graph topics are global, not under the namespace: the sensor
# writes /tf_static, /diagnostics and ros_discovery_info (docs/ros2.md), the
# others may read them.
graph="rt/tf_static rt/diagnostics ros_discovery_info"
permissions sensor "rt/$ns/* rr/$ns/* $graph" "rq/$ns/*"
permissions operator "rq/$ns/*" "rt/$ns/* rr/$ns/* $graph"
permissions viewer "" "rt/$ns/* $graph"
rm -f identity_ca.srl
echo "dds-security.sh: wrote CAs, identities (sensor operator viewer), permissions and governance to $(pwd)"
