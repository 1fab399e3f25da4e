//! The DDS Security XML documents (OMG DDS Security 1.1, 9.4.1.2-3), as SROS2 writes them.

use time::format_description::well_known::Rfc3339;
use time::OffsetDateTime;

use crate::policy::Grant;

/// The domains a keystore serves: every ROS domain id up to
/// [`msgs::enclave::MAX_SECURE_DOMAIN`] (230, not ROS's 232: Cyclone DDS's parser refuses
/// a governance or permissions document naming a domain above 230, so a keystore that
/// says 232 cannot be used by a Cyclone DDS node at all).
fn domains() -> String {
    format!(
        "<id_range><min>0</min><max>{}</max></id_range>",
        msgs::enclave::MAX_SECURE_DOMAIN
    )
}

/// The domain governance: SROS2's default. Unauthenticated participants are refused,
/// joining needs valid permissions, discovery and liveliness are encrypted, every RTPS
/// message is signed, and every topic has read and write access control with data and
/// metadata encrypted.
pub fn governance_xml() -> String {
    let domains = domains();
    format!(
        r#"<?xml version="1.0" encoding="UTF-8"?>
<dds xmlns:xsi="http://www.w3.org/2001/XMLSchema-instance" xsi:noNamespaceSchemaLocation="http://www.omg.org/spec/DDS-SECURITY/20170901/omg_shared_ca_governance.xsd">
  <domain_access_rules>
    <domain_rule>
      <domains>{domains}</domains>
      <allow_unauthenticated_participants>false</allow_unauthenticated_participants>
      <enable_join_access_control>true</enable_join_access_control>
      <discovery_protection_kind>ENCRYPT</discovery_protection_kind>
      <liveliness_protection_kind>ENCRYPT</liveliness_protection_kind>
      <rtps_protection_kind>SIGN</rtps_protection_kind>
      <topic_access_rules>
        <topic_rule>
          <topic_expression>*</topic_expression>
          <enable_discovery_protection>true</enable_discovery_protection>
          <enable_liveliness_protection>true</enable_liveliness_protection>
          <enable_read_access_control>true</enable_read_access_control>
          <enable_write_access_control>true</enable_write_access_control>
          <metadata_protection_kind>ENCRYPT</metadata_protection_kind>
          <data_protection_kind>ENCRYPT</data_protection_kind>
        </topic_rule>
      </topic_access_rules>
    </domain_rule>
  </domain_access_rules>
</dds>
"#
    )
}

/// XML text escaping for names we put into documents.
fn esc(s: &str) -> String {
    s.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
        .replace('"', "&quot;")
}

fn xsd_datetime(t: OffsetDateTime) -> String {
    let t = t
        .to_offset(time::UtcOffset::UTC)
        .replace_nanosecond(0)
        .unwrap_or(t);
    t.format(&Rfc3339).unwrap_or_default()
}

/// One enclave's permissions: a single grant for `subject` (the identity certificate's
/// subject, e.g. `CN=/tending/robot_3`), valid over `[not_before, not_after]`, allowing
/// `grant`'s topics and denying everything else.
pub fn permissions_xml(
    grant_name: &str,
    subject: &str,
    not_before: OffsetDateTime,
    not_after: OffsetDateTime,
    grant: &Grant,
) -> String {
    let topics = |list: &[String]| -> String {
        list.iter()
            .map(|t| format!("            <topic>{}</topic>\n", esc(t)))
            .collect()
    };
    let domains = domains();
    format!(
        r#"<?xml version="1.0" encoding="UTF-8"?>
<dds xmlns:xsi="http://www.w3.org/2001/XMLSchema-instance" xsi:noNamespaceSchemaLocation="http://www.omg.org/spec/DDS-SECURITY/20170901/omg_shared_ca_permissions.xsd">
  <permissions>
    <grant name="{name}">
      <subject_name>{subject}</subject_name>
      <validity>
        <not_before>{nb}</not_before>
        <not_after>{na}</not_after>
      </validity>
      <allow_rule>
        <domains>{domains}</domains>
        <publish>
          <topics>
{publish}          </topics>
        </publish>
        <subscribe>
          <topics>
{subscribe}          </topics>
        </subscribe>
      </allow_rule>
      <default>DENY</default>
    </grant>
  </permissions>
</dds>
"#,
        name = esc(grant_name),
        subject = esc(subject),
        nb = xsd_datetime(not_before),
        na = xsd_datetime(not_after),
        publish = topics(&grant.publish),
        subscribe = topics(&grant.subscribe),
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::policy::Role;

    #[test]
    fn permissions_name_the_subject_validity_and_topics() {
        let nb = OffsetDateTime::from_unix_timestamp(1_700_000_000).unwrap();
        let na = nb + time::Duration::days(1);
        let x = permissions_xml(
            "/tending/robot_3",
            "CN=/tending/robot_3",
            nb,
            na,
            &Role::Robots(vec!["robot_3".into()]).grant(),
        );
        assert!(x.contains("<subject_name>CN=/tending/robot_3</subject_name>"));
        assert!(x.contains("<not_before>2023-11-14T22:13:20Z</not_before>"));
        assert!(x.contains("<not_after>2023-11-15T22:13:20Z</not_after>"));
        assert!(x.contains("<topic>rt/robot_3/cmd_vel</topic>"));
        assert!(x.contains("<default>DENY</default>"));
    }

    /// Cyclone DDS 0.10's access control refuses to parse a document with a domain id
    /// above 230 (governance: code 137, permissions: 138); 232 was here before.
    #[test]
    fn documents_name_no_domain_above_230() {
        let nb = OffsetDateTime::from_unix_timestamp(1_700_000_000).unwrap();
        let p = permissions_xml("/x", "CN=/x", nb, nb, &Role::Bridge.grant());
        for doc in [governance_xml(), p] {
            assert!(
                doc.contains("<domains><id_range><min>0</min><max>230</max></id_range></domains>"),
                "{doc}"
            );
            for (i, _) in doc.match_indices("<max>") {
                let v: u32 = doc[i + 5..].split('<').next().unwrap().parse().unwrap();
                assert!(v <= 230, "{doc}");
            }
        }
    }

    #[test]
    fn governance_refuses_unauthenticated_participants() {
        let g = governance_xml();
        assert!(g.contains(
            "<allow_unauthenticated_participants>false</allow_unauthenticated_participants>"
        ));
        assert!(g.contains("<enable_write_access_control>true</enable_write_access_control>"));
    }
}
