#!/usr/bin/env bash
# Creates the DDS Security material for sl-sensor (docs/operations.md, "DDS Security"):
# an identity CA and a permissions CA, one identity (certificate + key) and
# one signed permissions document per role, and the two signed governance
# documents. Everything is written to OUT (default ./dds-security); keys are
# mode 0600. Uses openssl only.
#
#   bash scripts/dds-security.sh [OUT] [--domain N] [--ns NAMESPACE] [--days D]
#                                [--ca-from DIR]
#
# --ca-from DIR takes the two CAs (certificates and keys) from an earlier
# OUT instead of creating new ones: sensors of several namespaces under one
# pair of CAs.
#
# Roles (identities):
#   sensor    the daemon: publishes the sensor's rt/<ns>/ topics and the
#             replies rr/<ns>/<service>Reply, reads the requests
#   operator  slctl and clients that control the sensor: writes requests,
#             reads replies, status and data
#   viewer    reads status and data only; its requests are refused
# Every rule names exact topics (the ones dds/src/topic_names.cpp and the
# services spell), never a wildcard: `*` also matches `/`, so rq/<ns>/* would
# give an operator of namespace X the requests of a sensor in X/b.
# Governance (choose with SL_DDS_GOVERNANCE when running, see
# config/cyclonedds-security.xml):
#   governance_control  requests, replies and status authenticated, access-
#                       controlled and encrypted; the data topics (points,
#                       images, maps, camera_info, tf_static, diagnostics)
#                       signed (SIGN) with write access control: only the
#                       `sensor` identity publishes them, any authenticated
#                       participant may read them, a participant without
#                       security neither reads nor writes them
#   governance_origin   as governance_control, and every sample of a data
#                       topic carries a MAC per matched reader (metadata
#                       SIGN_WITH_ORIGIN_AUTHENTICATION): a reader, which
#                       holds the writer's common key, cannot forge a sample
#                       towards another reader either
#   governance_all      every topic protected and encrypted; participants
#                       without a valid identity are not admitted at all
set -euo pipefail
out=./dds-security domain=0 ns=sl days=3650 ca_from=
while [ $# -gt 0 ]; do
  case $1 in
    --domain) domain=$2; shift 2 ;;
    --ns) ns=$2; shift 2 ;;
    --days) days=$2; shift 2 ;;
    --ca-from) ca_from=$(cd "$2" && pwd) || exit 2; shift 2 ;;
    -h|--help) sed -n 2,39p "$0"; exit 0 ;;
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
# The namespace names the identities (OU), '/' written as '.' (a '/' would
# end the openssl subject's field; no namespace has a '.').
ou=${ns//\//.}
subj_base="/O=sl-sensor/OU=$ou"
not_before=$(date -u +%Y-%m-%dT%H:%M:%S)
not_after=$(date -u -d "+$days days" +%Y-%m-%dT%H:%M:%S)

ca() {  # name
  if [ -n "$ca_from" ]; then
    for f in "$1_ca_key.pem" "$1_ca.pem"; do
      [ -f "$ca_from/$f" ] || { echo "dds-security.sh: --ca-from: no $ca_from/$f" >&2; exit 2; }
      [ "$ca_from" = "$(pwd)" ] || cp "$ca_from/$f" .
    done
    return
  fi
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

# The sensor's topics by exact name (dds/src/topic_names.cpp, the services of
# dds/src/ros2_service.cpp and daemon/src/service_bridge.cpp). The ROS 2
# graph topics are global, not under the namespace: the sensor writes
# rt/tf_static, rt/diagnostics and ros_discovery_info (docs/ros2.md).
data=""
for t in points projector_maps image_sets depth/image shading/image camera_info \
         depth/image_rect depth/camera_info shading/camera_info shading/image/compressed \
         depth/image_rect/compressedDepth; do
  data="$data rt/$ns/$t"
done
status="rt/$ns/status"
requests="" replies=""
for s in command start stop set_pattern list_patterns get_config; do
  requests="$requests rq/$ns/${s}Request"
  replies="$replies rr/$ns/${s}Reply"
done
graph_data="rt/tf_static rt/diagnostics"
graph="$graph_data ros_discovery_info"

# protection: none | sign (writers access-controlled, samples signed: any
# authenticated reader, only permitted writers) | encrypt (both ways
# access-controlled, encrypted)
topic_rule() {  # expression protection
  local discovery=false read=false write=false kind=NONE meta=
  case $2 in
    sign) write=true kind=SIGN ;;
    origin) write=true kind=SIGN meta=SIGN_WITH_ORIGIN_AUTHENTICATION ;;
    encrypt) discovery=true read=true write=true kind=ENCRYPT ;;
  esac
  meta=${meta:-$kind}
  cat <<XML
        <topic_rule>
          <topic_expression>$1</topic_expression>
          <enable_discovery_protection>$discovery</enable_discovery_protection>
          <enable_liveliness_protection>$discovery</enable_liveliness_protection>
          <enable_read_access_control>$read</enable_read_access_control>
          <enable_write_access_control>$write</enable_write_access_control>
          <metadata_protection_kind>$meta</metadata_protection_kind>
          <data_protection_kind>$kind</data_protection_kind>
        </topic_rule>
XML
}

governance() {  # name data-protection(sign|origin|encrypt)
  local allow_unauth=true discovery=NONE rest=none
  [ "$2" = encrypt ] && { allow_unauth=false; discovery=ENCRYPT; rest=encrypt; }
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
    for t in $requests $replies $status; do topic_rule "$t" encrypt; done
    for t in $data $graph_data; do topic_rule "$t" "$2"; done
    topic_rule "*" "$rest"
    cat <<XML
      </topic_access_rules>
    </domain_rule>
  </domain_access_rules>
</dds>
XML
  } > "$1.xml"
  sign "$1.xml" "$1.p7s"
}
governance governance_control sign
governance governance_origin origin
governance governance_all encrypt

permissions() {  # role publish-topics subscribe-topics [probe-topic]
  {
    cat <<XML
<?xml version="1.0" encoding="UTF-8"?>
<dds xmlns:xsi="http://www.w3.org/2001/XMLSchema-instance"
     xsi:noNamespaceSchemaLocation="http://www.omg.org/spec/DDS-SECURITY/20170901/omg_shared_ca_permissions.xsd">
  <permissions>
    <grant name="$1">
      <subject_name>CN=$1,OU=$ou,O=sl-sensor</subject_name>
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
    # The daemon's cloud writer probes the points topic in a partition of its
    # own (dds/src/cloud_writer.cpp, kProbePartition): its writer and reader
    # meet only each other.
    if [ -n "${4:-}" ]; then
      for kind in publish subscribe; do
        echo "        <$kind><topics><topic>$4</topic></topics>"
        echo "          <partitions><partition>sl_internal_cloud_writer_probe</partition></partitions></$kind>"
      done
    fi
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
permissions sensor "$data $status $replies $graph" "$requests" "rt/$ns/points"
permissions operator "$requests" "$data $status $replies $graph"
permissions viewer "" "$data $status $graph"
rm -f identity_ca.srl
echo "dds-security.sh: wrote CAs, identities (sensor operator viewer), permissions and governance to $(pwd)"
