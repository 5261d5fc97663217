//! The UDP follow stream: LOCATION datagrams from the connected app's address only.

mod common;

use common::{localhost, other_host, value_of, Gateway};
use skymesh_solo_gateway::client::{AppClient, FollowStreamer};
use solo_proto::{ids, Location, SoloMessage};

fn here(n: u32) -> Location {
    Location {
        lat_deg: 37.8734 + f64::from(n) * 1e-5,
        lon_deg: -122.3012,
        alt_m: 1.5,
    }
}

#[tokio::test]
async fn follow_datagrams_are_forwarded_only_from_the_apps_address() {
    let mut gw = Gateway::start().await;
    let app_side = FollowStreamer::bind(localhost(), gw.udp)
        .await
        .expect("udp");
    let stranger = FollowStreamer::bind(other_host(), gw.udp)
        .await
        .expect("udp");

    // No app connected yet.
    app_side.send(here(0)).await.expect("send");
    gw.wait_malformed("no_app", 1.0).await;

    let _app = AppClient::connect_from(localhost(), gw.tcp)
        .await
        .expect("connect");
    gw.wait_connected(1).await;
    stranger.send(here(1)).await.expect("send");
    gw.wait_malformed("unauthorised", 1.0).await;
    let mut long = SoloMessage::Location(here(2)).to_bytes().to_vec();
    long.push(0);
    app_side.send_raw(&long).await.expect("send");
    app_side
        .send_raw(&SoloMessage::Pause.to_bytes())
        .await
        .expect("send");
    gw.wait_malformed("bad_datagram", 2.0).await;

    app_side.send(here(3)).await.expect("send");
    let got = gw.next_from_app().await;
    assert!(got.is_follow_stream());
    assert_eq!((got.session, got.msg_type), (1, ids::LOCATION));
    assert_eq!(
        got.value(),
        value_of(&SoloMessage::Location(here(3))).as_slice()
    );
    gw.wait_metric(
        "skymesh_solo_follow_datagrams_total",
        "result=forwarded",
        1.0,
    )
    .await;
    gw.wait_metric("skymesh_solo_follow_datagrams_total", "result=dropped", 4.0)
        .await;
    gw.stop().await;
}
